"""``benchmarks/schedules.py``: its rows and its table, from runs written by hand."""

import dataclasses

import pytest

from benchmarks import schedules
from solar_jax.cli import parse_config
from solar_jax.config import SCHEDULES, config_to_dict
from solar_jax.stats import welch_interval
from solar_jax.training.rundir import flatten


def test_every_ablation_row_puts_one_key_back_to_the_paper_s():
    rows = schedules.all_rows()

    def values(argv: list[str]) -> dict:
        return flatten(config_to_dict(parse_config([*schedules.DEFAULTS, *argv])))

    fast, paper = values(rows["fast"]), values([])
    assert [n for n in rows if n.startswith("no-")] == [f"no-{k}" for k in SCHEDULES["fast"]]
    for key in SCHEDULES["fast"]:
        row = values(rows[f"no-{key}"])
        assert row[key] == paper[key] != fast[key], key
        # Every other key stays the fast schedule's.
        assert {k: v for k, v in row.items() if k != key} == {
            k: v for k, v in fast.items() if k != key
        }, key


def test_seeds_and_the_table():
    assert schedules.parse_seeds("0-3") == [0, 1, 2, 3]
    assert schedules.parse_seeds("5,2") == [5, 2]
    runs = [
        schedules.Run("fast", seed, final, final, 100_000, 25_000, 250.0 + seed, 4.0)
        for seed, final in ((1, 2_000.0), (0, 900.0), (2, 1_300.0))
    ]
    data = {"runs": {"fast": [dataclasses.asdict(r) for r in runs], "paper": []}}
    lines = schedules.table(data).splitlines()
    assert len(lines) == 3  # a row without runs is left out
    cells = [c.strip() for c in lines[2].split("|")[1:-1]]
    assert cells[:3] == ["fast", "900, 2,000, 1,300", "2 of 3"]  # by seed; >= 1,000
    assert cells[3].startswith("1,400 [") and cells[-1] == "251 / 252 (4)"


def test_unknown_rows_are_one_error_line(capsys):
    valid = f"valid: {', '.join(schedules.all_rows())}, or ROW+KEY=VALUE"
    for bad in ("slow", "fast+round_steps"):
        assert schedules.main([f"rows=fast,{bad}"]) == 2
        assert capsys.readouterr().err.strip() == f"error: unknown row {bad!r}; {valid}"


def test_a_row_with_keys_of_its_own():
    base = schedules.all_rows()
    rows = schedules.resolve_rows(["fast+round_steps=32+eval_envs=4", "paper"], base)
    assert rows == {
        "fast+round_steps=32+eval_envs=4": [*base["fast"], "round_steps=32", "eval_envs=4"],
        "paper": base["paper"],
    }


@pytest.mark.parametrize("bad", ["td3.lrr=1", "seeds=0-1 td3.lr=-1"])
def test_a_bad_train_key_is_one_error_line_before_anything_runs(bad, capsys):
    assert schedules.main(bad.split()) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: ") and "td3.lr" in err and err.count("\n") == 1


def test_methods_cross_the_rows_and_a_time_limit_replaces_the_step_budgets():
    rows = schedules.crossed(schedules.all_rows(timed=True), ["solar", "amorpheus"])
    assert list(rows)[:4] == ["fast/solar", "fast/amorpheus", "paper/solar", "paper/amorpheus"]
    for name, keys in rows.items():
        config = parse_config(["morph=hopper_3", "time_limit=1200", *keys])
        assert config.method == name.split("/")[1] and config.time_limit == 1200
        assert config.total_steps == 10_000_000, name  # the limit, not PAPER_STEPS, ends it
    assert schedules.crossed({"fast": ["schedule=fast"]}, []) == {"fast": ["schedule=fast"]}
    assert f"total_steps={schedules.PAPER_STEPS}" in schedules.all_rows()["paper"]


def test_differences_against_a_row():
    def runs(row, finals):
        return [
            dataclasses.asdict(schedules.Run(row, s, f, f, 1, 1, 1.0, 0.0))
            for s, f in enumerate(finals)
        ]

    data = {
        "runs": {
            "paper": runs("paper", [100.0, 120.0, 110.0]),
            "fast": runs("fast", [300.0, 340.0, 320.0]),
            "one": runs("one", [5.0]),  # one seed: no interval, left out
        }
    }
    low, high = welch_interval([300.0, 340.0, 320.0], [100.0, 120.0, 110.0])
    lines = schedules.differences(data, "paper").splitlines()
    assert lines[2:] == [f"| fast | +210 [{low:+,.0f}, {high:+,.0f}] |"] and 0 < low < 210
    with pytest.raises(ValueError, match="against=one: expected a row of two or more seeds"):
        schedules.differences(data, "one")


def test_against_an_unknown_row_is_one_error_line(capsys):
    assert schedules.main(["rows=fast,paper", "against=slow"]) == 2
    assert capsys.readouterr().err.strip() == "error: against=slow is not a row; rows: fast, paper"
