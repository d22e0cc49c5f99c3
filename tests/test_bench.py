"""``python -m solar_jax.bench``: its grammar (train's keys and each part's own on one
parser, one-line errors), the robots each learner row times, and ``all``'s summary and
exit status when a part fails. The parts' measurements run at tiny sizes in
``tests/test_commands.py`` (slow: ``benchmarks/gpu.py size=tiny`` and the startup test)."""

import json

import pytest

from solar_jax.bench import __main__ as bench
from solar_jax.bench import common, learner, physics
from solar_jax.cli import plain
from solar_jax.config import ConfigError, TrainConfig


def test_the_command_lists_its_parts_and_names_an_unknown_one(capsys):
    assert bench.main(["--help"]) == 0
    assert "physics|learner|train|startup|all" in capsys.readouterr().out
    assert bench.main([]) == 2
    assert bench.main(["throughput"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1
    assert "'throughput': expected one of physics, learner, train, startup, all" in err


@pytest.mark.parametrize("part", [*bench.PARTS, "all"])
def test_every_part_answers_help_with_its_own_options_and_train_s(part, capsys):
    assert bench.main([part, "--help"]) == 0
    out = capsys.readouterr().out
    doc = (bench.ALL if part == "all" else bench.PARTS[part]).doc
    assert plain(doc.strip().splitlines()[0]) in out
    assert "  out=" in out and "  morph=humanoid++" in out and "``" not in out


def test_own_keys_go_to_the_part_and_the_rest_to_train_s_config():
    config, options, rest = common.parse(
        ["morph=hopper_3", "steps=3", "batch_sizes=2,4", "env.solver_iterations=2"],
        physics.Options(),
    )
    assert (config.morph, config.env.solver_iterations) == ("hopper_3", 2)
    assert (options.steps, options.batch_sizes, options.native) == (3, (2, 4), True)
    assert rest == ["morph=hopper_3", "env.solver_iterations=2"]


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["batch_size=4"], "did you mean td3.batch_size or batch_sizes?"),
        (["stepz=4"], "did you mean steps?"),
        (["steps=0"], "steps and batch_sizes must be >= 1"),
        (["batch_sizes=2,x"], "batch_sizes=x: expected int"),
        (["native=maybe"], "native=maybe: expected a boolean"),
        (["td3.lr=fast"], "td3.lr=fast: expected float"),
        (["steps"], "'steps': arguments are key=value"),
    ],
)
def test_a_bad_argument_is_one_line_naming_it(argv, message):
    with pytest.raises(ConfigError, match=message.replace("?", r"\?")):
        common.parse(argv, physics.Options())


def test_a_bad_argument_exits_2_before_measuring(capsys, tmp_path):
    out = tmp_path / "x.json"
    assert bench.main(["learner", "presets=huge", f"out={out}"]) == 2
    assert bench.main(["all", "parts=train,train", f"out={out}"]) == 2
    assert bench.main(["physics", "morph=hopper_99", f"out={out}"]) == 2
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 3 and all(line.startswith("error: ") for line in err)
    assert "presets=huge: expected one of default, small, tiny" in err[0]
    assert "hopper_99" in err[2]
    assert not out.exists()


def test_learner_rows_time_the_suite_s_largest_robot_alone_and_all_together():
    config = TrainConfig(morph="hopper++")
    groups = {
        u: learner.robot_groups(config, learner.Options(), u) for u in ("sequential", "fused")
    }
    assert groups == {"sequential": [["hopper_5"]], "fused": [["hopper_3", "hopper_4", "hopper_5"]]}
    named = learner.Options(robots=("walker_7_main", "hopper++"))
    assert learner.robot_groups(config, named, "sequential") == [
        ["walker_7_main"],
        ["hopper_3"],
        ["hopper_4"],
        ["hopper_5"],
    ]
    assert learner.robot_groups(config, named, "fused") == [
        ["hopper_3", "hopper_4", "hopper_5"],
        ["walker_7_main"],
    ]


def test_all_keeps_the_other_parts_when_one_fails_and_exits_1(monkeypatch, capsys, tmp_path):
    def measured(config, options, config_argv=()):
        row = dict(backend="mjx", batch=config.num_envs, compile_s=1.5, env_steps_per_s=1234.0)
        return {"rows": [row]}

    def broken(config, options, config_argv=()):
        raise RuntimeError("out of memory")

    fake = {
        "physics": common.Part("physics", "", physics.Options(), measured, lambda r: "table"),
        "learner": common.Part("learner", "", learner.Options(), broken, lambda r: "table"),
    }
    monkeypatch.setattr(bench, "PARTS", fake)
    path = tmp_path / "all.json"
    assert bench.main(["all", "parts=physics,learner", "num_envs=3", f"out={path}"]) == 1
    out = capsys.readouterr()
    assert "| physics | mjx, batch 3 | 1.5 | 1,234 | - |" in out.out
    assert "| learner | failed | - | - | - |" in out.out
    assert "out of memory" in out.err
    saved = json.loads(path.read_text())
    assert saved["parts"]["physics"]["result"]["rows"][0]["env_steps_per_s"] == 1234.0
    assert "out of memory" in saved["parts"]["learner"]["error"]
    assert saved["meta"]["argv"] == ["parts=physics,learner", "num_envs=3", f"out={path}"]
    assert saved["meta"]["versions"]["jax"] and saved["meta"]["device"]
