"""A whole run on CPU (``tests.tiny``: an Euler hopper_3 from an MJCF file, tiny
networks): kill and resume, tracing, the run directory, the CLI.

The in-process runs share the session's compiled round, and the command-line run its
configuration, so the subprocess loads the compiled round from the persistent cache.
"""

import dataclasses
import json
import os
import subprocess
import sys

import jax
import numpy as np
import pytest

from solar_jax.cli import parse_config
from solar_jax.config import (
    METHOD_KEYS,
    METHODS,
    SCHEDULES,
    ConfigError,
    NetworkConfig,
    TD3Config,
    TrainConfig,
    config_from_dict,
    config_to_dict,
)
from solar_jax.train import main
from solar_jax.training.checkpoint import Checkpointer
from solar_jax.training.lanes import SingleLane
from solar_jax.training.logger import read_metrics
from solar_jax.training.programs import RoundPrograms
from solar_jax.training.rundir import CHECKPOINTS, check_same_run, flatten
from solar_jax.training.runner import Runner, restore_run
from solar_jax.training.trainer import PER_WORLD_MIN_CPUS, Trainer
from tests.conftest import REPO
from tests.tiny import ARGS, BOUNDED, CONFIG, NAME, ROBOT, Killed


@pytest.fixture
def programs(tiny_run) -> RoundPrograms:
    return tiny_run


def _without_timings(records: list[dict]) -> list[dict]:
    return [{k: v for k, v in r.items() if not k.startswith("perf/")} for r in records]


def _run_killed_at(env_steps: int, config: TrainConfig, programs: RoundPrograms) -> None:
    """Runs ``config`` and dies (``Killed``) at the end of its first round at or past
    ``env_steps``, as a process killed between two rounds."""

    def kill(state, records):
        if records[0]["env_steps"] >= env_steps:
            raise Killed

    with pytest.raises(Killed):
        Runner(config, programs).run(on_round=kill)


def test_kill_and_resume_and_a_raised_budget_equal_the_uninterrupted_run(tmp_path, programs):
    traces, compiled = dict(programs.traces), programs.compiled
    new_sizes = len({1024, 2048} - set(programs.programs))  # replay sizes not compiled yet
    # Rounds end near 125, 325, 485, 644, ... counted steps; checkpoints on crossing 300 and
    # 600, so the run killed at its first round past 450 loses that round.
    config = dataclasses.replace(CONFIG, total_steps=900, checkpoint_every=300, eval_every=400)
    full = Runner(dataclasses.replace(config, out=str(tmp_path / "full")), programs).run()
    # The replay grew on the way (1024 slots, then 2048 past 624 stored transitions).
    assert full.replay.capacity == 2048

    killed_dir = tmp_path / "killed"
    _run_killed_at(450, dataclasses.replace(config, out=str(killed_dir)), programs)
    killed_log = read_metrics(killed_dir)
    checkpointer = Checkpointer(killed_dir / CHECKPOINTS)
    assert killed_log[-1]["round"] > checkpointer.latest_step()  # a round lost with the process
    checkpointer.close()
    resumed = Runner(parse_config([f"resume={killed_dir}"]), programs).run()
    assert resumed.env_steps >= 900
    # A finished shorter run, resumed with a raised budget (its replay saved at 1024).
    short_dir = tmp_path / "short"
    Runner(dataclasses.replace(config, total_steps=500, out=str(short_dir)), programs).run()
    raised = Runner(parse_config([f"resume={short_dir}", "total_steps=900"]), programs).run()
    # A run stopped by its time limit after its first round, resumed without one.
    timed_dir = tmp_path / "timed"
    Runner(dataclasses.replace(config, time_limit=1e-9, out=str(timed_dir)), programs).run()
    stopped = read_metrics(timed_dir)
    assert [(r["kind"], r["round"]) for r in stopped] == [("eval", 0), ("round", 1), ("eval", 1)]
    checkpointer = Checkpointer(timed_dir / CHECKPOINTS)
    assert checkpointer.latest_step() == 1
    checkpointer.close()
    timed = Runner(parse_config([f"resume={timed_dir}", "time_limit=0"]), programs).run()

    full_log = _without_timings(read_metrics(tmp_path / "full"))
    resumed_runs = ((resumed, killed_dir, 0), (raised, short_dir, 1), (timed, timed_dir, 1))
    for state, run_dir, extra_evals in resumed_runs:
        for name in ("agent", "replay", "synergy", "key", "env_steps", "updates", "rounds"):
            jax.tree.map(np.testing.assert_array_equal, getattr(full, name), getattr(state, name))
        log = _without_timings(read_metrics(run_dir))
        extra = [r for r in log if r not in full_log]  # an evaluation where the run stopped
        assert [r for r in log if r not in extra] == full_log
        assert len(extra) == extra_evals and all(r["kind"] == "eval" for r in extra)
    best = [Checkpointer(d / CHECKPOINTS / "best") for d in (tmp_path / "full", killed_dir)]
    assert best[0].latest_step() == best[1].latest_step() is not None  # the same best round
    for checkpointer in best:
        checkpointer.close()
    assert [r["kind"] for r in full_log].count("eval") == 4  # at 0, past 400 and 800, the end
    # Over 7 runs and 4 restores: the physics traced once, whatever the replay's size;
    # storing and updating once per replay size (two sizes; other tests of the session
    # may have compiled some of them already).
    assert programs.traces == {
        "collect": traces["collect"] + (not compiled),
        "close": traces["close"] + new_sizes,
        "train": traces["train"] + new_sizes,
        "evaluate": 0,  # evaluations through the collection's program
    }


def test_kill_and_resume_mid_episode_equal_the_uninterrupted_run_in_bounded_rounds(
    tmp_path, tiny_bounded
):
    # The fast schedule's rounds of 25 steps (tests.tiny.BOUNDED): 100 transitions a
    # round, 95-100 counted; checkpoints on crossing 400 and 800, so the run killed at its
    # first round past 550 loses that round, and its environments are mid-episode there.
    config = dataclasses.replace(BOUNDED, total_steps=1000, checkpoint_every=400)
    assert (config.update, config.num_envs, config.td3.update_every) == ("fused", 4, 2)
    full = Runner(dataclasses.replace(config, out=str(tmp_path / "full")), tiny_bounded).run()

    killed_dir = tmp_path / "killed"
    _run_killed_at(550, dataclasses.replace(config, out=str(killed_dir)), tiny_bounded)
    checkpointer = Checkpointer(killed_dir / CHECKPOINTS)
    saved = checkpointer.latest_step()
    checkpointer.close()
    assert read_metrics(killed_dir)[-1]["round"] > saved > 0
    trainer = tiny_bounded.trainer
    restored, _, checkpointer = restore_run(trainer, config, killed_dir)
    checkpointer.close()
    steps = np.asarray(restored.envs.worlds[0].steps)
    assert bool(restored.envs.started) and np.all(steps > 0)  # every episode under way
    resumed = Runner(parse_config([f"resume={killed_dir}"]), tiny_bounded).run()
    assert resumed.updates == full.updates > 0 and resumed.env_steps >= 1000
    for name in ("agent", "replay", "synergy", "key", "env_steps", "updates", "rounds", "envs"):
        jax.tree.map(np.testing.assert_array_equal, getattr(full, name), getattr(resumed, name))
    full_log = _without_timings(read_metrics(tmp_path / "full"))
    assert _without_timings(read_metrics(killed_dir)) == full_log
    assert all(r["updates"] <= r["env_steps"] // 2 for r in full_log if r["kind"] == "round")


@pytest.mark.slow  # 31 s alone: its own collection and update programs
def test_smp_trains_through_the_trainer(tmp_path):
    # The limb tree built from the robot, SMP's per-limb Q through collection, updates,
    # evaluation and the checkpoint.
    short = ["total_steps=150", "eval_every=0", "checkpoint_every=0"]  # the warm-up, a round
    config = parse_config([*ARGS, *short, "method=smp", f"out={tmp_path}"])
    programs = RoundPrograms(SingleLane(Trainer(config)))
    assert [s.tolist() for s in programs.trainer.tree.senders] == [[[0]], [[1]]]  # torso, thigh
    state = Runner(config, programs).run()
    assert state.updates > 0 and state.env_steps >= 150
    assert all(bool(np.all(np.isfinite(x))) for x in jax.tree.leaves(state.agent.critic))
    evals = [r for r in read_metrics(tmp_path) if r["kind"] == "eval"]
    assert len(evals) >= 2 and all(np.isfinite(r["eval/train_return"]) for r in evals)


def test_run_directory_contents(tmp_path, programs):
    config = dataclasses.replace(CONFIG, out=str(tmp_path / "run"))
    Runner(config, programs).run()
    saved = json.loads((tmp_path / "run" / "config.json").read_text())
    assert saved["config"]["morph"] == str(ROBOT) and saved["config"]["td3"]["warmup_steps"] == 100
    assert saved["config"]["network"]["width"] == 16  # net=tiny, resolved in the config
    assert saved["resolved"]["morphologies"] == [NAME]
    records = read_metrics(tmp_path / "run")
    round_ = next(r for r in records if r["kind"] == "round")
    for key in (
        f"episode/{NAME}/return",
        f"episode/{NAME}/length",
        "episode/train_return",
        "loss/critic",
        "loss/actor",
        "perf/env_sps",
        "perf/update_sps",
        f"synergy/{NAME}/num_clusters",
        f"synergy/{NAME}/exemplars",
        f"synergy/{NAME}/labels",
        f"actions/{NAME}/saturated",
        f"actions/{NAME}/pre_tanh_rms",
        f"actions/{NAME}/gate_rms",
        "train_env_steps",
        "heldout_steps",
    ):
        assert key in round_, key
    assert 0 <= round_[f"actions/{NAME}/saturated"] <= 1 and round_[f"actions/{NAME}/gate_rms"] > 0
    assert round_["train_env_steps"] == round_["env_steps"] and round_["heldout_steps"] == 0
    assert round_["updates"] == round_["env_steps"]  # one update per counted step, M = 1
    evals = [r for r in records if r["kind"] == "eval"]
    assert {f"eval/{NAME}/return", "eval/train_return"} <= set(evals[-1])
    assert evals[-1]["env_steps"] >= CONFIG.total_steps  # the final evaluation
    # The policy at the best evaluation after round 0, kept beside the latest checkpoint.
    trained = [r for r in evals if r["round"] > 0]
    best = max(trained, key=lambda r: r["eval/train_return"])
    best_dir = tmp_path / "run" / CHECKPOINTS / "best"
    assert [p.name for p in best_dir.iterdir() if p.name.isdigit()] == [str(best["round"])]
    from solar_jax.viz.video import restore

    _, policy, step = restore(tmp_path / "run", "best")
    assert step == best["round"] and isinstance(policy.agent.actor["trunk"], dict)
    assert all(isinstance(x, jax.Array) for x in jax.tree.leaves(policy.agent.actor))
    with pytest.raises(Exception, match="already holds a run"):
        Runner(config, programs).run()


def test_train_command_runs(tmp_path):
    """The command as a user runs it, with ``MUJOCO_GL=osmesa`` (a broken backend where
    libOSMesa is absent; training never touches OpenGL): quiet output, the summary
    (whose numbers are the metrics file's) and the figures at the end."""
    out = tmp_path / "cli"
    # A user's shell: importing jax here set TF_CPP_MIN_LOG_LEVEL=1 in this process.
    env = {k: v for k, v in os.environ.items() if k != "TF_CPP_MIN_LOG_LEVEL"}
    result = subprocess.run(
        [sys.executable, "-m", "solar_jax.train", *ARGS, f"out={out}"],
        capture_output=True,
        text=True,
        cwd=REPO,
        timeout=900,
        env={**env, "MUJOCO_GL": "osmesa"},
    )
    assert result.returncode == 0, result.stderr[-3000:]
    for noise in ("Failed to import", "cpu_aot_loader", "pjrt_executable", "Traceback"):
        assert noise not in result.stdout + result.stderr, noise
    records = read_metrics(out)
    assert records[-1]["kind"] == "eval" and records[-1]["env_steps"] >= CONFIG.total_steps
    assert sorted(p.name for p in (out / "checkpoints").iterdir())  # orbax step folders
    rounds = [r for r in records if r["kind"] == "round"]
    lines = result.stdout.splitlines()
    assert f"{NAME}, solar, paper schedule: {records[-1]['env_steps']:,} env steps" in result.stdout
    row = next(line for line in lines if line.startswith(f"{NAME} ")).split()
    noisy = np.mean([r[f"episode/{NAME}/return"] for r in rounds[-10:]])
    trained = [r for r in records if r["kind"] == "eval" and r["round"] > 0]
    best = max(trained, key=lambda r: r[f"eval/{NAME}/return"])
    assert row[1:] == [
        "train",
        f"{records[0][f'eval/{NAME}/return']:,.1f}",
        f"{records[-1][f'eval/{NAME}/return']:,.1f}",
        f"{best[f'eval/{NAME}/return']:,.1f}",
        "@",
        f"{best['env_steps']:,}",
        f"{noisy:,.1f}",
        "-",  # no expert return for a user's robot (tests/test_commands.py: the ones with)
        str(rounds[-1][f"synergy/{NAME}/num_clusters"]),
    ]
    compile_s = sum(r.get("perf/compile_s", 0.0) for r in records)
    assert f"compile {compile_s:,.0f}," in result.stdout
    figures = [line.removeprefix("figure: ") for line in lines if line.startswith("figure: ")]
    names = ["curves-eval.png", "curves-episode.png", "synergy-latest.png", "clusters.png"]
    assert figures == [str(out / "plots" / name) for name in names]
    assert all((out / "plots" / name).stat().st_size > 1000 for name in names)


@pytest.mark.slow
def test_train_command_resumes_a_finished_run_to_more_steps(tmp_path):
    out = tmp_path / "cli"
    first = subprocess.run(
        [sys.executable, "-m", "solar_jax.train", *ARGS, f"out={out}"],
        capture_output=True,
        text=True,
        cwd=REPO,
        timeout=900,
    )
    assert first.returncode == 0, first.stderr[-3000:]
    second = subprocess.run(
        [
            sys.executable,
            "-m",
            "solar_jax.train",
            f"resume={out}",
            "total_steps=600",
            "progress=false",
        ],
        capture_output=True,
        text=True,
        cwd=REPO,
        timeout=900,
    )
    assert second.returncode == 0, second.stderr[-3000:]
    assert read_metrics(out)[-1]["env_steps"] >= 600


@pytest.mark.parametrize(
    "argv, message",
    [
        (["colour=red"], "unknown config key 'colour' (--help lists the keys)"),
        (["td3.lrr=1e-3"], "unknown config key 'td3.lrr'; did you mean td3.lr?"),
        (["lr=1e-3"], "unknown config key 'lr'; did you mean td3.lr?"),
        (["td3.speed=2"], "unknown config key 'td3.speed'; td3's keys: td3.lr, td3.synergy_lr"),
        (["network.mlp_hidden=64,x"], "network.mlp_hidden=x: expected int"),
        (["network.mlp_hidden=,"], "network.mlp_hidden=,: expected comma-separated items"),
        (["method=sac"], "method=sac: expected one of solar, solar_no_pref, amorpheus"),
        (["td3.lr=fast"], "td3.lr=fast: expected float"),
        (["update=parallel"], "update=parallel: expected one of sequential, fused"),
        (["morph=hopper_9"], "unknown suite or morphology 'hopper_9'"),
        (["total_steps=0"], "total_steps must be >= 1"),
        (["time_limit=-60"], "time_limit must be >= 0, got -60.0"),
        (["time_limit=inf"], "time_limit must be a finite number, got inf"),
        (["resume=/nonexistent/run"], "no config.json there"),
    ],
)
def test_bad_input_is_one_clear_error(argv, message, capsys):
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert message in err and err.count("\n") == 1, err


def test_resume_refuses_to_change_the_run(tmp_path):
    (tmp_path / "config.json").write_text(
        json.dumps({"config": dataclasses.asdict(CONFIG), "resolved": {"replay_capacity": 1000}})
    )
    with pytest.raises(ValueError, match="cannot change morph, td3.lr of a saved run"):
        parse_config([f"resume={tmp_path}", "morph=walker++", "td3.lr=1"])
    resumed = parse_config([f"resume={tmp_path}", "total_steps=5000"])
    assert resumed.total_steps == 5000 and resumed.replay_capacity == CONFIG.replay_capacity
    assert resumed.network == CONFIG.network  # the tiny preset, as saved


def test_a_checkpoint_from_before_a_key_existed_resumes_at_its_default(tmp_path):
    saved = config_to_dict(CONFIG)
    del saved["time_limit"], saved["network"]["message_dim"]  # keys added later
    config = config_from_dict(TrainConfig, saved)
    check_same_run(tmp_path, config, saved)  # they ran with the defaults: the same run
    with pytest.raises(ConfigError, match="network.message_dim 4 .checkpoint: None."):
        changed = dataclasses.replace(config.network, message_dim=4)
        check_same_run(tmp_path, dataclasses.replace(config, network=changed), saved)


def test_tiny_preset_takes_network_overrides():
    config = parse_config(["net=tiny", "network.width=32", "network.heads=4"])
    assert config.network.width == 32 and config.network.heads == 4
    assert config.network.num_layers == 2  # the rest of the preset
    assert TrainConfig(net="tiny").network == NetworkConfig.tiny()  # programmatic
    assert dataclasses.replace(config, seed=1).network == config.network  # kept, not replaced
    assert TD3Config().transform_lr == 1e-4 and TD3Config(synergy_lr=3e-4).transform_lr == 3e-4


def test_tuples_and_whole_floats_parse():
    config = parse_config(["network.mlp_hidden=64, 32", "total_steps=2e6", "seed=1.0"])
    assert config.network.mlp_hidden == (64, 32)
    assert (config.total_steps, config.seed) == (2_000_000, 1)
    assert parse_config(["network.mlp_hidden=(128,)"]).network.mlp_hidden == (128,)
    with pytest.raises(ConfigError, match="total_steps=2.5: expected int"):
        parse_config(["total_steps=2.5"])


def test_a_schedule_sets_its_keys_and_the_command_line_s_go_on_top():
    paper = parse_config(["morph=hopper_3"])
    assert (paper.schedule, paper.num_envs, paper.td3.update_every) == ("paper", 1, 1)
    fast = parse_config(["schedule=fast", "morph=hopper_3"])
    assert fast.schedule == "fast"
    values, paper_values = flatten(config_to_dict(fast)), flatten(config_to_dict(paper))
    for key, text in SCHEDULES["fast"].items():
        expected = flatten(config_to_dict(parse_config([f"{key}={text}"])))[key]
        assert values[key] == expected != paper_values[key], key  # the schedule's, not the paper's
    # Given keys win, in any order; the net preset applies under the schedule's network.*.
    mine = parse_config(["num_envs=4", "schedule=fast", "net=tiny", "td3.update_every=2"])
    assert (mine.num_envs, mine.td3.update_every, mine.update) == (4, 2, "fused")
    assert mine.network == dataclasses.replace(NetworkConfig.tiny(), torso_action=False)
    assert parse_config(["schedule=fast", "network.torso_action=true"]).network.torso_action
    assert config_from_dict(TrainConfig, config_to_dict(mine)) == mine
    with pytest.raises(ConfigError, match="schedule=slow: expected one of paper, fast"):
        parse_config(["schedule=slow"])
    with pytest.raises(ConfigError, match="td3.update_every must be >= 1"):
        parse_config(["td3.update_every=0"])


def test_a_method_sets_its_own_keys_under_the_command_line_s():
    # SMP's reference scripts clip no gradient (METHOD_KEYS); the others keep section 5's.
    assert parse_config(["method=smp"]).td3.grad_clip == 0.0
    assert parse_config(["method=amorpheus"]).td3.grad_clip == 0.1
    assert parse_config(["td3.grad_clip=0.3", "method=smp"]).td3.grad_clip == 0.3
    fast = parse_config(["schedule=fast", "method=smp"])  # both sets of keys
    assert (fast.td3.grad_clip, fast.num_envs) == (0.0, 16)
    assert set(METHOD_KEYS) <= set(METHODS)
    with pytest.raises(ConfigError, match="td3.grad_clip must be >= 0"):
        parse_config(["td3.grad_clip=-1"])


def test_dry_run_prints_the_plan(capsys):
    assert main(["morph=walker++", "net=tiny", "total_steps=20000", "dry_run=true"]) == 0
    out = capsys.readouterr().out
    assert "held out: walker_3_main, walker_6_main" in out
    # The reference's ring and counting (held-out morphologies too, M_all = 6, algorithm.md §5).
    assert "replay: 1,000,000 transitions per morphology" in out
    assert "allocated as it fills, from 2,048" in out
    assert "warm-up 12,000" in out
    assert "exploration noise std 0.126" in out
    # The six walkers as variants of walker_7_main's tree: one MJX model, one program.
    assert "physics: 1 MJX model(s): walker_7_main's tree holds 6 robots" in out
    assert "collection: 1 program(s) for 1 MJX world(s) (collect=auto)" in out
    # A model per robot: two cores or fewer (the CI's): the six in one program; more: one each.
    assert main(["morph=walker++", "net=tiny", "env.layout=per_robot", "dry_run=true"]) == 0
    out = capsys.readouterr().out
    programs = 6 if (os.cpu_count() or 1) >= PER_WORLD_MIN_CPUS else 1
    assert f"collection: {programs} program(s) for 6 MJX world(s) (collect=auto)" in out
    assert "robots: nominal (env.variation off)" in out
    argv = ["morph=hopper_3", "net=tiny", "dry_run=true", "env.variation=dynamics"]
    assert main([*argv, "env.variation_pool=3"]) == 0
    assert (
        "robots: domain randomisation over dynamics (a pool of 3 per robot"
        in capsys.readouterr().out
    )
