"""The commands' help, experiment files and end-of-run summary, without training:
``--help`` lists every key with its default and docstring, every file in
``experiments/`` is one the commands accept, and the summary's numbers are the
metrics file's."""

import json
from pathlib import Path

import numpy as np
import pytest

from solar_jax import plot, rollout, sweep, train
from solar_jax.cli import _entries, plain, valid_keys
from solar_jax.config import ConfigError, TrainConfig
from solar_jax.experiments import expand, load_experiment
from solar_jax.viz.report import EXPERT_RETURNS, Redraw, format_summary, summary
from solar_jax.viz.runs import load_run
from tests.conftest import REPO
from tests.viz.fake_runs import write_run

EXPERIMENTS = sorted((REPO / "experiments").glob("*.toml"))
COMMANDS = {
    "train": (train.main, TrainConfig()),
    "sweep": (sweep.main, TrainConfig()),
    "plot": (plot.main, plot.PlotOptions()),
    "rollout": (rollout.main, rollout.RolloutConfig()),
}


@pytest.mark.parametrize("command", COMMANDS)
def test_help_lists_every_key_with_its_default_and_docstring(command, capsys):
    main, config = COMMANDS[command]
    assert main(["--help"]) == 0
    text = capsys.readouterr().out
    for key in valid_keys(type(config)):
        value = _nested(config, key)
        shown = "none" if value is None else value
        shown = str(shown).lower() if isinstance(shown, bool) else shown
        shown = ",".join(map(str, shown)) if isinstance(shown, tuple) else shown
        assert f"  {key}={shown}  (" in text, key
    assert "``" not in text  # the docstrings' markup is not for the terminal
    undocumented = [e[0] for entries in _entries(config).values() for e in entries if not e[2]]
    assert not undocumented, undocumented


def _nested(config, dotted: str):
    for part in dotted.split("."):
        config = getattr(config, part)
    return config


def test_help_narrows_to_a_section(capsys):
    assert train.main(["--help", "td3"]) == 0
    text = capsys.readouterr().out
    assert "td3.lr=0.0001" in text and "env.solver_iterations" not in text
    assert "seeds=4" in (sweep.main(["--help"]), capsys.readouterr().out)[1]
    assert train.main(["--help", "nope"]) == 2
    err = capsys.readouterr().err
    assert err == "error: --help nope: no such section; sections: network, env, td3\n"


@pytest.mark.parametrize("path", EXPERIMENTS, ids=[p.stem for p in EXPERIMENTS])
def test_every_experiment_file_is_valid(path):
    """Each variant's keys parse as its command's (a sweep's lanes validate too), and
    the file says what it costs."""
    experiment = load_experiment(path)
    assert experiment.description and "CPU" in experiment.expected
    parse = train.parse_config if experiment.command == "train" else sweep.parse_sweep
    runs = expand([str(path), "out=runs/x"], experiment.command)
    assert [name for name, _ in runs] == [name for name, _ in experiment.variants]
    outs = set()
    for _, arguments in runs:
        parsed = parse(arguments)
        config = parsed if experiment.command == "train" else parsed.config
        outs.add(config.out)
    assert len(outs) == len(runs)  # each variant its own directory


def test_quickstart_is_a_train_experiment():
    assert load_experiment(REPO / "experiments" / "quickstart.toml").command == "train"


@pytest.mark.parametrize(
    "text, message",
    [
        ('command = "sweep"', "missing description, expected, config"),
        (
            'description = "d"\ncommand = "fly"\nexpected = "CPU"\n[config]\n',
            "command=fly: expected one of train, sweep",
        ),
        (
            'description = "d"\ncommand = "train"\nexpected = "CPU"\n[config.td3]\nlr = 1\n',
            '[config].td3 is a table; write dotted keys quoted, e.g. "td3.<field>" = ...',
        ),
        ("description = ", "not valid TOML"),
    ],
)
def test_bad_experiment_files_are_one_clear_error(tmp_path, text, message):
    path = tmp_path / "bad.toml"
    path.write_text(text)
    with pytest.raises(ConfigError, match="^" + str(path).replace(".", r"\.")) as err:
        load_experiment(path)
    assert message in str(err.value)
    assert train.main([str(path)]) == 2


def test_an_experiment_runs_with_its_own_command(capsys):
    path = str(REPO / "experiments" / "humanoid_multitask.toml")
    assert train.main([path]) == 2
    err = capsys.readouterr().err
    assert "is a sweep experiment: run it with python -m solar_jax.sweep" in err


def _logged_run(path: Path) -> Path:
    """walker++ (4 training, 2 held-out robots) with 12 rounds and 3 evaluations in the
    runner's format, per-robot numbers known; each round's update time 0.5 s plus 10 ms
    per iteration."""
    write_run(path, "walker++", "solar")  # config.json
    names = load_run(path).names
    records, updates = [], 0
    for r in range(13):
        if r in (0, 6, 12):  # the evaluation at round 6 is each robot's best: 10 i + 30
            record = {"kind": "eval", "round": r, "env_steps": 100 * r, "updates": updates}
            record |= {
                f"eval/{n}/return": 10.0 * i + r + 24 * (r == 6) for i, n in enumerate(names)
            }
            records.append(record | {"perf/eval_s": 2.0, "perf/compile_s": 30.0 * (r == 0)})
        if r == 12:
            break
        iterations = 50 + 25 * (r % 4)
        updates += iterations
        record = {"kind": "round", "round": r + 1, "env_steps": 100 * (r + 1), "updates": updates}
        record |= {f"episode/{n}/return": 100.0 * i + r for i, n in enumerate(names)}
        record |= {f"synergy/{n}/num_clusters": 2 + i + (r > 5) for i, n in enumerate(names)}
        record |= {"perf/collect_s": 1.0, "perf/train_s": 0.5 + 0.01 * iterations}
        records.append(record | {"perf/compile_s": 5.0 * (r == 3)})
    records.sort(key=lambda x: (x["env_steps"], x["kind"] == "eval"))
    (path / "metrics.jsonl").write_text("".join(json.dumps(x) + "\n" for x in records))
    return path


def test_summary_numbers_are_the_metrics_files(tmp_path):
    run = load_run(_logged_run(tmp_path / "run"))
    s = summary(run)
    assert (s.env_steps, s.suite, s.method) == (1200, "walker++", "solar")
    for i, row in enumerate(s.rows):
        assert row.held_out == (row.name in ("walker_3_main", "walker_6_main"))
        assert (row.initial, row.final) == (10.0 * i, 10.0 * i + 12)
        assert (row.best, row.best_step) == (10.0 * i + 30, 600)
        assert row.noisy == np.mean([100.0 * i + r for r in range(2, 12)])  # the last 10
        assert row.normalised == pytest.approx((10.0 * i + 12) / EXPERT_RETURNS[row.name])
        assert row.synergies == 3 + i
    t = s.timing
    assert (t.compile_s, t.collect_s, t.eval_s, t.rounds) == (35.0, 12.0, 6.0, 12)
    assert t.update_s == pytest.approx(12 * 0.5 + 0.01 * s.updates)
    assert t.round_cost_s == pytest.approx(0.5)  # the intercept
    text = format_summary(s, [Path("a.png"), Path("a.svg")])
    assert text.splitlines()[-1] == "figure: a.png"
    assert "mean (train)" in text and "mean (held out)" in text
    assert "30.0 @ 600" in text  # the first robot's best
    assert "0.50 s/round x 12 rounds = 6 s" in text


def test_live_figures_are_redrawn_at_most_once_a_minute_with_every_lane_evaluated():
    now = [0.0]
    drawn = []
    redraw = Redraw(
        lambda dirs: drawn.append(dirs) or [Path(f"{d}.png") for d in dirs], 60.0, lambda: now[0]
    )
    assert redraw([Path("a")]) == [] and drawn == []  # 0 s after the start
    now[0] = 59.0
    assert redraw([Path("b")]) == [] and drawn == []
    now[0] = 61.0  # lanes evaluated while it waited are drawn with the next
    assert redraw([Path("a")]) == [Path("a.png"), Path("b.png")]
    now[0] = 100.0
    assert redraw([Path("b")]) == [] and drawn == [[Path("a"), Path("b")]]
    now[0] = 121.0
    assert redraw([]) == [Path("b.png")]


def test_expert_returns_cover_every_reference_robot():
    from solar_jax.morphology import get_suite

    names = {
        n
        for suite in ("walker++", "hopper++", "humanoid++", "cheetah++")
        for n in get_suite(suite).members
    }
    assert names <= set(EXPERT_RETURNS)


def test_warnings_before_waste():
    """The paper's sizes on a CPU are flagged before compiling, with a lower bound from
    the measured update cost; any run whose own rate projects past 2 h, after its first
    rounds; short runs and small networks say nothing."""
    from solar_jax.training.forecast import long_run_warning, paper_on_cpu_warning
    from solar_jax.training.logger import duration

    paper = train.parse_config(["morph=humanoid++"])
    text = paper_on_cpu_warning(paper, 6, 8)
    assert "~7,500,000 TD3 updates" in text and "at least 2.3 days" in text
    assert paper_on_cpu_warning(train.parse_config(["morph=humanoid++", "net=small"]), 6, 8) is None
    assert paper_on_cpu_warning(train.parse_config(["total_steps=1000"]), 6, 8) is None
    assert "take about 27.8 h" in long_run_warning(100, 10_000_000, 100, 1.0)
    assert long_run_warning(100, 30_000, 100, 1.0) is None  # 5 minutes left
    assert [duration(s) for s in (42, 210, 7.1 * 3600, 12.3 * 86400)] == [
        "42 s",
        "3.5 min",
        "7.1 h",
        "12.3 days",
    ]


@pytest.mark.parametrize(
    "name",
    [
        "ablation",
        "affinity",
        "compile",
        "drift",
        "gpu",
        "learner",
        "learning",
        "mjx_step",
        "recluster",
        "reference",
    ],
)
def test_every_benchmark_answers_help(name, capsys):
    import importlib

    module = importlib.import_module(f"benchmarks.{name}")
    try:
        code = module.main(["--help"])
    except SystemExit as exit_:  # benchmarks.options exits after help
        code = exit_.code
    assert code in (0, None)
    out = capsys.readouterr().out
    assert out.strip() and plain(module.__doc__.strip().splitlines()[0])[:40] in out
    assert "``" not in out  # the docstrings' markup is not for the terminal


def test_the_accelerator_script_names_unknown_or_repeated_parts(capsys, tmp_path):
    from benchmarks import gpu

    assert gpu.main([f"out={tmp_path}", "parts=train,training"]) == 2
    assert (
        "parts=train,training: expected some of train, sweep, physics, learner, "
        "physics_per_robot" in capsys.readouterr().err
    )
    assert gpu.main([f"out={tmp_path}", "parts=learner,learner"]) == 2
    assert "each once" in capsys.readouterr().err
    assert not any(tmp_path.iterdir())  # nothing ran


@pytest.mark.slow  # about 3 minutes of compilation on 2 cores
def test_the_accelerator_script_runs_every_part_on_tiny_sizes(tmp_path):
    # The script the first lent GPU runs (benchmarks/gpu.py), here on the CPU at tiny
    # sizes: every part runs through solar_jax.bench and lands in the one JSON with numbers.
    import json

    from benchmarks import gpu

    assert gpu.main(["size=tiny", f"out={tmp_path}"]) == 0
    (path,) = (p for p in tmp_path.glob("gpu_*.json") if not p.name.startswith("gpu_part_"))
    parts = json.loads(path.read_text())["parts"]
    assert set(parts) == {"learner", "physics", "train", "sweep", "physics_per_robot"}
    assert all(part["error"] is None for part in parts.values())
    learner = parts["learner"]["result"]
    assert [r["update"] for r in learner["rows"]] == ["sequential", "fused"]
    assert all(r["ms_per_iteration"] > 0 and r["gflop_per_s"] > 0 for r in learner["rows"])
    assert learner["square_gemm_gflop_per_s"] > 0
    assert learner["meta"]["versions"]["jax"]
    for name, layout in (("physics", "union"), ("physics_per_robot", "per_robot")):
        (row,) = parts[name]["result"]["rows"]
        assert row["layout"] == layout and row["env_steps_per_s"] > 0
    training = parts["train"]["result"]
    assert [r["update"] for r in training["rows"]] == ["sequential", "fused"]
    assert all(r["iterations_per_s"] > 0 for r in training["rows"])
    (row,) = parts["sweep"]["result"]["rows"]
    assert row["lanes"] == 2 and row["update"] == "fused" and row["iterations_per_s"] > 0
    assert 0 < row["predicted_peak_bytes"] < row["device_bytes_limit"]


@pytest.mark.slow  # two tiny runs, one compiling, one from the cache
def test_the_startup_benchmark_times_a_cold_and_a_warm_start(tmp_path):
    import json

    from solar_jax.bench.__main__ import main

    args = ["net=tiny", "replay_capacity=4096", "td3.warmup_steps=100"]
    path = tmp_path / "startup.json"
    assert main(["startup", "morph=hopper_3", *args, f"out={path}"]) == 0
    cold, warm = json.loads(path.read_text())["rows"]
    assert (cold["cache"], warm["cache"]) == ("cold", "warm")
    for row in (cold, warm):
        assert 0 < row["compiling_s"] < row["first_step_s"] <= row["first_update_s"]
        assert row["first_update_s"] <= row["first_round_s"] < row["wall_s"]
    assert warm["compile_s"] < cold["compile_s"]  # loaded from the persistent cache


def test_progress_eta_extrapolates_the_rate_since_the_first_update():
    from solar_jax.training.logger import ProgressBar

    bar = ProgressBar(1000, enabled=False)
    assert bar.eta(10.0, 100) == "-"  # the first update: no rate yet
    assert bar.eta(40.0, 400) == "60 s"  # 300 steps in 30 s; 600 left
    assert bar.eta(130.0, 400) == "4.0 min"  # 300 steps in 120 s; 600 left
    assert bar.eta(200.0, 1000) == "-"  # done
