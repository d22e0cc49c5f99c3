"""``python -m solar_jax.evaluate``: zero-shot to variants on the session's two-seed tiny
sweep (an Euler hopper_3), one program for the nominal robot and all its variants."""

import json

import numpy as np
import pytest

from solar_jax.evaluate import _reusable, main
from solar_jax.training.rundir import checkpoint_steps
from solar_jax.training.zeroshot import NOMINAL, summarise


@pytest.mark.slow  # its episodes' program: 45-65 s to compile on 2 cores
def test_zero_shot_table_of_a_two_seed_sweep(tiny_sweep, tmp_path, capsys):
    sweep_dir = tiny_sweep[0]
    argv = [str(sweep_dir), "variants=armature,gear,limb_height", "per_property=2"]
    assert main([*argv, f"out={tmp_path}"]) == 0
    out = capsys.readouterr().out
    payload = json.loads((tmp_path / "zeroshot.json").read_text())
    runs = payload["runs"]
    assert [r["run"] for r in runs] == [str(sweep_dir / "seed0"), str(sweep_dir / "seed1")]
    labels = [NOMINAL, "armature", "armature", "gear", "gear", "limb_height", "limb_height"]
    for run in runs:
        assert run["labels"] == labels and run["robots"] == ["hopper_3_euler"]
        returns, lengths = np.asarray(run["returns"]), np.asarray(run["lengths"])
        assert returns.shape == lengths.shape == (1, 7)
        assert ((1 <= lengths) & (lengths <= 200)).all() and np.isfinite(returns).all()
        assert len(np.unique(returns)) == 7  # every variant is its own robot
        own = json.loads(
            (sweep_dir / run["run"].rsplit("/", 1)[-1] / "zeroshot/returns.json").read_text()
        )
        assert own == run
    # One group (the method), its interval over the two seeds' means.
    (group,) = payload["table"]
    table = payload["table"][group]
    assert list(table) == [NOMINAL, "armature", "gear", "limb_height"]
    for label, row in table.items():
        means = [np.mean(np.asarray(r["returns"])[0, np.asarray(labels) == label]) for r in runs]
        assert row["mean"] == pytest.approx(np.mean(means)) and row["runs"] == 2
        assert row["ci95"][0] <= row["mean"] <= row["ci95"][1]
        assert row["ratio"] == pytest.approx(row["mean"] / table[NOMINAL]["mean"])
    assert "| armature |" in out and (tmp_path / "zeroshot.png").is_file()
    assert (tmp_path / "zeroshot.md").read_text().startswith("| variants | solar")
    # reuse=true tabulates what each run wrote under the same options, without running.
    capsys.readouterr()
    assert main([*argv, "reuse=true", f"out={tmp_path / 'reused'}"]) == 0
    assert capsys.readouterr().out.count("from ") == 2
    reused = json.loads((tmp_path / "reused" / "zeroshot.json").read_text())
    assert reused["table"] == payload["table"]
    # Returns written under other options, or unreadable, are evaluated again.
    stamped = sweep_dir / "seed1" / "zeroshot" / "returns.json"
    stamp = json.loads(stamped.read_text())["evaluated_with"]
    assert stamp["checkpoints"] == checkpoint_steps(sweep_dir / "seed1")
    assert _reusable(stamped, stamp) and not _reusable(stamped, {**stamp, "seed": 1})
    assert not _reusable(stamped, {**stamp, "checkpoints": [*stamp["checkpoints"], 999]})
    stamped.write_text("{")
    assert not _reusable(stamped, stamp)


def test_one_run_s_interval_is_over_its_robots_and_variants():
    result = {"labels": [NOMINAL, "gear", "gear"], "returns": [[10.0, 4.0, 8.0], [30.0, 6.0, 2.0]]}
    table = summarise({"solar": [result]})["solar"]
    assert table[NOMINAL]["mean"] == 20.0 and table["gear"]["mean"] == 5.0
    assert table["gear"]["ratio"] == 0.25 and table["gear"]["runs"] == 1
    low, high = table["gear"]["ci95"]
    assert low < 5.0 < high


@pytest.mark.parametrize(
    "argv, message",
    [
        (["variants=density=0:1"], "variation density: range 0:1 must be positive"),
        (["variants=mass"], "unknown variation property 'mass'"),
        (["per_property=0"], "per_property must be >= 1, got 0"),
        (["checkpoint=first"], "checkpoint"),
        ([], "no run directories given"),
    ],
)
def test_bad_input_is_one_line(argv, message, tmp_path, capsys):
    paths = [] if not argv or argv == [] else [str(tmp_path)]
    assert main([*paths, *argv]) == 2
    err = capsys.readouterr().err
    assert message in err and err.count("\n") == 1
