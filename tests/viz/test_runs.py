"""Reading run and sweep directories, and grouping seeds into labelled lines."""

import json

import pytest

from solar_jax.viz.runs import VizError, flatten, group_runs, load_run, load_runs, run_dirs
from tests.viz.fake_runs import write_run, write_sweep


def test_runs_group_by_suite_method_and_varying_config(tmp_path):
    paths = [
        write_run(tmp_path / "a0", "walker++", "solar", seed=0, lr=1e-4),
        write_run(tmp_path / "a1", "walker++", "solar", seed=1, lr=1e-4),
        write_run(tmp_path / "b0", "walker++", "solar", seed=0, lr=3e-4),
        write_run(tmp_path / "c0", "walker++", "amorpheus", seed=0, lr=1e-4),
        write_run(tmp_path / "d0", "hopper++", "solar", seed=0),
        write_run(tmp_path / "d1", "hopper++", "solar", seed=1),
    ]
    groups = group_runs(load_runs(paths))
    # Seeds, run directories (out) and the like never split a line; td3.lr does, but
    # only in the suite where it varies.
    members = {key: [run.path.name for run in runs] for key, runs in groups.items()}
    assert members == {
        ("walker++", "solar td3.lr=0.0001"): ["a0", "a1"],
        ("walker++", "solar td3.lr=0.0003"): ["b0"],
        ("walker++", "amorpheus td3.lr=0.0001"): ["c0"],
        ("hopper++", "solar"): ["d0", "d1"],
    }


def test_a_schedule_names_a_line_without_the_keys_it_sets(tmp_path):
    paths = [
        write_run(tmp_path / "p0", "hopper++", seed=0),
        write_run(tmp_path / "f0", "hopper++", seed=0, schedule="fast"),
        write_run(tmp_path / "f1", "hopper++", seed=1, schedule="fast"),
        write_run(tmp_path / "g0", "hopper++", seed=0, schedule="fast", tau=0.01),
    ]
    labels = [label for _, label in group_runs(load_runs(paths))]
    # td3.lr, num_envs, ... differ with the schedule alone; td3.tau within the fast runs.
    assert labels == [
        "solar schedule=paper td3.tau=0.046",
        "solar schedule=fast td3.tau=0.046",
        "solar schedule=fast td3.tau=0.01",
    ]


def test_a_run_reads_its_suite_split(tmp_path):
    run = load_run(write_run(tmp_path / "run", "walker++"))
    assert run.names[: run.num_train] == (
        "walker_2_main",
        "walker_4_main",
        "walker_5_main",
        "walker_7_main",
    )
    assert run.held_out == ("walker_3_main", "walker_6_main")
    assert run.has_synergies and run.config["td3.lr"] == 1e-4
    assert not load_run(write_run(tmp_path / "base", method="amorpheus")).has_synergies


def test_flatten_nests_with_dots_and_makes_lists_hashable():
    assert flatten({"a": 1, "td3": {"lr": 2}, "net": {"mlp": [3, 4]}}) == {
        "a": 1,
        "td3.lr": 2,
        "net.mlp": (3, 4),
    }


def test_sweep_directories_expand_into_their_lanes(tmp_path):
    sweep = write_sweep(
        tmp_path / "sweep",
        [{"seed": 0, "lr": 1e-4}, {"seed": 1, "lr": 1e-4}, {"seed": 0, "lr": 3e-4}],
    )
    single = write_run(tmp_path / "single", seed=5)
    found = run_dirs([sweep, single])
    assert found == [sweep / "lane0", sweep / "lane1", sweep / "lane2", single]
    with pytest.raises(VizError, match=f"a sweep's file, not a run; pass the sweep {sweep}$"):
        run_dirs([sweep / "sweep.json", single])  # what runs/SWEEP/* expands to
    groups = group_runs(load_runs([sweep]))
    assert {label: len(runs) for (_, label), runs in groups.items()} == {
        "solar td3.lr=0.0001": 2,
        "solar td3.lr=0.0003": 1,
    }


def test_bad_directories_are_one_clear_error(tmp_path):
    with pytest.raises(VizError, match="no run directories given"):
        run_dirs([])
    with pytest.raises(VizError, match="not a run directory .* nor a sweep directory"):
        run_dirs([tmp_path])
    run = write_run(tmp_path / "run")
    (run / "metrics.jsonl").write_text("")
    with pytest.raises(VizError, match="metrics.jsonl is empty"):
        load_run(run)
    (run / "metrics.jsonl").unlink()
    with pytest.raises(VizError, match="no metrics.jsonl"):
        load_run(run)
    (tmp_path / "empty_sweep").mkdir()
    (tmp_path / "empty_sweep" / "sweep.json").write_text(json.dumps({"lanes": []}))
    with pytest.raises(VizError, match="lists no lanes"):
        run_dirs([tmp_path / "empty_sweep"])
