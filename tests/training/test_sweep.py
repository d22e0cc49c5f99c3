"""Sweeps (``tests.tiny``: an Euler hopper_3 from an MJCF file, tiny networks):
lanes equal single runs, hyper-parameter lanes, sharding over the session's two fake
CPU devices, kill and resume, the CLI.

The single runs share the session's compiled round of one lane (``tiny_run``); every
sweep here has two lanes and shares the session's compiled two-lane round
(``tiny_lanes``): both are ``RoundPrograms``, run by the same ``Runner``.
"""

import dataclasses
import json
import os
import subprocess
import sys

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from solar_jax.config import ConfigError
from solar_jax.sweep import AGGREGATE_FILE, SWEEP_FILE, main, parse_sweep
from solar_jax.training import rundir
from solar_jax.training.lanes import DEVICE_LANES_AXIS, LANE_AXIS, Lanes, lane, lane_devices
from solar_jax.training.logger import read_metrics
from solar_jax.training.programs import RoundPrograms
from solar_jax.training.runner import Runner
from solar_jax.training.sweep import SweepRunner
from tests import unoptimised
from tests.conftest import REPO
from tests.tiny import ARGS, BOUNDED, BOUNDED_ARGS, CONFIG, Killed


@pytest.fixture
def single(tiny_run) -> RoundPrograms:
    return tiny_run


@pytest.fixture
def lanes(tiny_lanes) -> RoundPrograms:
    return tiny_lanes


@pytest.fixture
def seeds_sweep(tiny_sweep):
    return tiny_sweep


def _without_timings(records: list[dict]) -> list[dict]:
    return [{k: v for k, v in r.items() if not k.startswith("perf/")} for r in records]


def _assert_same_run(single: list[dict], swept: list[dict], rtol: float) -> None:
    """Identical discrete outcomes (steps, lengths, clusters); floats within ``rtol``:
    vmapped arithmetic may round differently from the single program's."""
    assert len(single) == len(swept)
    for a, b in zip(_without_timings(single), _without_timings(swept), strict=True):
        assert a.keys() == b.keys()
        for key, value in a.items():
            if isinstance(value, float) and not key.endswith("/length"):
                np.testing.assert_allclose(b[key], value, rtol=rtol, atol=1e-3, err_msg=key)
            else:
                assert b[key] == value, key


def _assert_lanes_are_single_runs(tmp_path, out, state, config, single) -> list:
    """Each seed's lane of the sweep in ``out`` (final ``state``) against its single run
    of ``config``: the same records and counters; returns the single runs' states."""
    states = []
    for seed in (0, 1):
        alone = Runner(
            dataclasses.replace(config, seed=seed, out=str(tmp_path / f"s{seed}")), single
        ).run()
        _assert_same_run(
            read_metrics(tmp_path / f"s{seed}"), read_metrics(out / f"seed{seed}"), 1e-3
        )
        swept = lane(state, seed)
        for name in ("env_steps", "updates", "rounds", "key"):
            np.testing.assert_array_equal(getattr(swept, name), getattr(alone, name))
        states.append(alone)
    return states


def test_two_seed_sweep_equals_two_single_runs(tmp_path, seeds_sweep, lanes, single):
    # The sweep first: when the tiny group has run first, on the other worker, this one
    # loads the single runs' programs from the session's persistent cache; else it
    # compiles them, for the tiny group too (tests/conftest.py).
    out, state = seeds_sweep
    expected_devices = min(jax.device_count(), 2)
    assert len(lanes.lanes.devices) == expected_devices
    assert len(state.agent.critic_opt[1].count.sharding.device_set) == expected_devices
    alone_runs = _assert_lanes_are_single_runs(tmp_path, out, state, CONFIG, single)
    for seed, alone in enumerate(alone_runs):
        swept = lane(state, seed)
        np.testing.assert_array_equal(swept.synergy.labels, alone.synergy.labels)
        jax.tree.map(
            lambda a, b: np.testing.assert_allclose(a, b, rtol=1e-2, atol=1e-3),
            swept.agent.actor,
            alone.agent.actor,
        )
    assert lanes.traces == {"collect": 1, "close": 1, "train": 1, "evaluate": 0}  # one for all

    # Lane directories are run directories of train's format.
    for seed in (0, 1):
        saved = json.loads((out / f"seed{seed}" / "config.json").read_text())
        assert saved["config"]["seed"] == seed
        assert saved["resolved"]["replay_capacity"] == 1_000_000  # the ring, allocated as it fills
        assert (out / f"seed{seed}" / "checkpoints").is_dir()
    sweep = json.loads((out / SWEEP_FILE).read_text())
    assert [entry["run_dir"] for entry in sweep["lanes"]] == ["seed0", "seed1"]


def test_a_finished_lane_idles_and_the_live_lane_collects_as_alone(lanes, seeds_sweep):
    """A finished lane runs no episode (its state is returned untouched, zero stats), so
    it cannot lengthen the live lane's round; the live lane collects exactly what it
    collects when both lanes are live."""
    _, final = seeds_sweep
    lanes.compile(final)
    keys = jax.random.split(jax.random.PRNGKey(0), 2)
    both = np.array([False, False])
    one_done = np.array([False, True])
    copy = unoptimised.copy(final)  # collect donates its state
    live_state, live_stats = lanes.collect(unoptimised.copy(final), keys, both, both)
    state, stats = lanes.collect(copy, keys, one_done, one_done)
    assert np.all(np.asarray(stats.episode_length)[1] == 0) and np.all(stats.steps[1] == 0)
    jax.tree.map(np.testing.assert_array_equal, lane(state, 1), lane(final, 1))
    jax.tree.map(np.testing.assert_array_equal, lane(state, 0), lane(live_state, 0))
    np.testing.assert_array_equal(stats.episode_return[0], live_stats.episode_return[0])


def test_lanes_sharing_a_device_are_vmapped_and_train_as_lanes_apart(lanes, seeds_sweep):
    """A sweep on one device (one GPU, several seeds) vmaps its lanes on it; it trains as
    the two devices with a lane each, and a finished lane keeps its state there too. (The
    update alone, at -O0: the episodes take the same path.)"""
    _, final = seeds_sweep
    lanes.compile(final)
    shared = Lanes(lanes.trainer, 2, devices=jax.devices()[:1])
    assert shared.device_lanes == 2 and shared.lane_axes == (DEVICE_LANES_AXIS, LANE_AXIS)
    steps = jnp.full((2, lanes.trainer.num_morphs), 10, jnp.int32)
    live = np.array([True, False])
    vmapped, metrics = unoptimised.jit(shared.train)(
        jax.device_put(final, shared.sharding), *shared.train_args(final, steps, live)[1:]
    )
    apart, expected = lanes.train(unoptimised.copy(final), steps, live)
    np.testing.assert_array_equal(vmapped.updates, [int(final.updates[0]) + 10, final.updates[1]])
    np.testing.assert_array_equal(vmapped.updates, apart.updates)
    jax.tree.map(np.testing.assert_array_equal, lane(vmapped.agent, 1), lane(final.agent, 1))
    jax.tree.map(
        lambda a, b: np.testing.assert_allclose(a, b, rtol=1e-3, atol=1e-4),
        (lane(vmapped.agent, 0), lane(metrics, 0)),
        (lane(apart.agent, 0), lane(expected, 0)),
    )


def test_aggregate_is_the_ci_of_the_lanes_last_evaluations(seeds_sweep):
    out, _ = seeds_sweep
    (variant,) = json.loads((out / AGGREGATE_FILE).read_text())["variants"]
    finals = [
        [r for r in read_metrics(out / f"seed{s}") if r["kind"] == "eval"][-1]["eval/train_return"]
        for s in (0, 1)
    ]
    stats = variant["eval/train_return"]
    assert stats["values"] == finals
    half = 12.706204736 * np.std(finals, ddof=1) / np.sqrt(2)  # t_{0.975, 1}
    np.testing.assert_allclose(stats["mean"], np.mean(finals))
    np.testing.assert_allclose(stats["ci95"], [np.mean(finals) - half, np.mean(finals) + half])


def test_killed_sweep_resumes_to_the_uninterrupted_one(tmp_path, lanes, seeds_sweep):
    full_dir, full = seeds_sweep
    out = tmp_path / "killed"

    def kill(state, records):
        if np.min(np.asarray(state.env_steps)) >= 200:  # both lanes checkpointed past 150
            raise Killed

    with pytest.raises(Killed):
        SweepRunner(parse_sweep(ARGS + ["seeds=2", f"out={out}"]), lanes).run(kill)
    resumed = SweepRunner(parse_sweep([f"resume={out}"]), lanes).run()
    for name in ("agent", "replay", "synergy", "key", "env_steps", "updates", "rounds"):
        jax.tree.map(np.testing.assert_array_equal, getattr(full, name), getattr(resumed, name))
    for seed in (0, 1):
        expected = _without_timings(read_metrics(full_dir / f"seed{seed}"))
        assert _without_timings(read_metrics(out / f"seed{seed}")) == expected


def test_learning_rate_lanes_train_with_their_own_rate(tmp_path, single, lanes, seeds_sweep):
    out = tmp_path / "lr"
    sweep = parse_sweep(ARGS + ["seeds=1", "td3.lr=[1e-4,1e-3]", f"out={out}"])
    assert [spec.name for spec in sweep.lanes] == ["td3.lr=0.0001-seed0", "td3.lr=0.001-seed0"]
    state = SweepRunner(sweep, lanes).run()
    rates = state.agent.actor_opt[1].hyperparams["learning_rate"]
    np.testing.assert_allclose(rates, [1e-4, 1e-3])
    fast = dataclasses.replace(CONFIG, out=str(tmp_path / "fast"))
    fast = dataclasses.replace(fast, td3=dataclasses.replace(fast.td3, lr=1e-3))
    Runner(fast, single).run()
    # A 10x larger rate amplifies the vmapped rounding differences round by round:
    # compare the first two rounds closely (~190 updates; each round already updates the
    # critic).
    single, swept = read_metrics(tmp_path / "fast"), read_metrics(out / "td3.lr=0.001-seed0")
    _assert_same_run(single[:4], swept[:4], 1e-3)
    # The 1e-4 lane is the seed sweep's lane 0 (same inputs, same program); 1e-3 is not.
    seeds_dir, _ = seeds_sweep
    default = _without_timings(read_metrics(seeds_dir / "seed0"))
    assert _without_timings(read_metrics(out / "td3.lr=0.0001-seed0")) == default
    quick = read_metrics(out / "td3.lr=0.001-seed0")
    actor_losses = [
        [r["loss/actor"] for r in log if r["kind"] == "round"] for log in (default, quick)
    ]
    losses = list(zip(*actor_losses, strict=False))
    assert max(abs(a - b) / abs(a) for a, b in losses) > 0.1
    saved = json.loads((out / "td3.lr=0.001-seed0" / "config.json").read_text())
    assert saved["config"]["td3"]["lr"] == 1e-3
    assert lanes.traces == {"collect": 1, "close": 1, "train": 1, "evaluate": 0}  # still one


def test_a_diverging_lane_stops_alone_and_the_other_runs_as_it_would(tmp_path, lanes, seeds_sweep):
    out = tmp_path / "diverging"
    sweep = parse_sweep(ARGS + ["seeds=1", "td3.lr=[1e-4,1e30]", f"out={out}"])
    runner = SweepRunner(sweep, lanes)
    runner.run()
    (failure,) = runner.runner.failures
    assert "td3.lr=1e+30-seed0: round 1: non-finite losses or parameters" in failure
    assert not rundir.has_checkpoint(out / "td3.lr=1e+30-seed0")  # nothing of NaN saved
    seeds_dir, _ = seeds_sweep
    default = _without_timings(read_metrics(seeds_dir / "seed0"))
    assert _without_timings(read_metrics(out / "td3.lr=0.0001-seed0")) == default


@pytest.mark.slow  # ~60 s: tracing the vmapped round dominates, the cache cannot skip it
def test_sweep_command_line(tmp_path, seeds_sweep):
    """The real command, loading the in-process sweep's programs from the session cache."""
    out = tmp_path / "cli"
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    command = [sys.executable, "-m", "solar_jax.sweep", *ARGS, "seeds=2", f"out={out}"]
    done = subprocess.run(command, cwd=tmp_path, env=env, capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    assert "final train return" in done.stdout and f"done -> {out}" in done.stdout
    assert {p.name for p in out.iterdir()} == {
        "seed0",
        "seed1",
        "plots",
        SWEEP_FILE,
        AGGREGATE_FILE,
    }
    assert f"figure: {out / 'plots' / 'curves-eval.png'}" in done.stdout
    assert (out / "seed1" / "plots" / "synergy-latest.png").is_file()
    expected_dir, _ = seeds_sweep
    assert _without_timings(read_metrics(out / "seed1")) == _without_timings(
        read_metrics(expected_dir / "seed1")
    )


def test_dry_run_and_errors_of_the_command(capsys):
    assert main([*ARGS, "seeds=3", "td3.tau=[0.005,0.046]", "dry_run=true"]) == 0
    out = capsys.readouterr().out
    assert "replay: 1,000,000 transitions per morphology" in out  # allocated as it fills
    assert "6 lanes (td3.tau=0.005-seed0, " in out and "on 2 device(s)" in out
    assert main([*ARGS, "seeds=3", "td3.batch_size=[1,2]"]) == 2
    assert capsys.readouterr().err.count("\n") == 1


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["td3.batch_size=[50,100]"], "only scalar hyper-parameters can be swept"),
        (["seeds=0"], "seeds=0: must be >= 1"),
        (["seeds=two"], "seeds=two: expected an int"),
        (["td3.lr=[1e-4"], "a list is written [a,b,...]"),
        (["td3.lr=[]"], "the list is empty"),
        (["td3.lr=[1e-4,1e-4]"], "a value is repeated"),
        (["td3.lr=[1e-4,-1]"], "td3.lr must be > 0"),
        (["td3.lr=[1e-4,fast]"], "td3.lr=fast: expected float"),
        (["bogus=[1,2]"], "unknown config key 'bogus'"),
        (["resume=/nonexistent"], "no sweep.json there"),
    ],
)
def test_bad_sweep_arguments_are_one_line_errors(argv, message):
    with pytest.raises(ConfigError, match=message.replace("[", r"\[").replace("]", r"\]")) as err:
        parse_sweep(argv)
    assert "\n" not in str(err.value)


def test_resume_refuses_to_change_a_sweep(seeds_sweep, lanes):
    out, _ = seeds_sweep
    with pytest.raises(ConfigError, match=f"already holds a sweep; continue it with resume={out}"):
        SweepRunner(parse_sweep([*ARGS, "seeds=2", f"out={out}"]), lanes).run()
    with pytest.raises(ConfigError, match="cannot change method"):
        parse_sweep([f"resume={out}", "method=amorpheus"])
    with pytest.raises(ConfigError, match="cannot change seeds"):
        parse_sweep([f"resume={out}", "seeds=3"])
    resumed = parse_sweep([f"resume={out}", "total_steps=900"])
    assert resumed.config.total_steps == 900 and resumed.seeds == (0, 1)
    assert all(spec.config.resume for spec in resumed.lanes)


def test_lane_of_device_or_host_arrays_and_a_lane_out_of_range():
    tree = {"a": jnp.arange(6.0).reshape(2, 3), "b": jnp.array([4, 5])}
    for stacked in (tree, jax.device_get(tree)):
        np.testing.assert_array_equal(lane(stacked, 1)["a"], [3.0, 4.0, 5.0])
        assert int(lane(stacked, -1)["b"]) == 5
        with pytest.raises(IndexError):
            lane(stacked, 2)


def test_lane_devices_divide_the_lanes():
    devices = ["a", "b", "c", "d"]
    assert lane_devices(4, devices) == devices
    assert lane_devices(6, devices) == ["a", "b", "c"]
    assert lane_devices(5, devices) == ["a"]


@pytest.mark.slow  # about 60 s: the two-lane round of bounded length compiles
def test_a_sweep_in_bounded_rounds_equals_its_single_runs(tmp_path, tiny_bounded):
    # Rounds of bounded length (tests.tiny.BOUNDED): each lane's environments go on from
    # round to round as its single run's; a finished lane's stay as they were.
    out = tmp_path / "sweep"
    lanes = RoundPrograms(Lanes(tiny_bounded.trainer, 2))
    sweep = parse_sweep([*BOUNDED_ARGS, "seeds=2", "total_steps=400", f"out={out}"])
    state = SweepRunner(sweep, lanes).run()
    config = dataclasses.replace(BOUNDED, total_steps=400)
    alone_runs = _assert_lanes_are_single_runs(tmp_path, out, state, config, tiny_bounded)
    for seed, alone in enumerate(alone_runs):
        swept = lane(state, seed)
        np.testing.assert_array_equal(swept.envs.worlds[0].steps, alone.envs.worlds[0].steps)
        np.testing.assert_allclose(swept.envs.worlds[0].obs, alone.envs.worlds[0].obs, atol=1e-3)
    keys = jax.random.split(jax.random.PRNGKey(0), 2)
    both, one_done = np.array([False, False]), np.array([False, True])
    lanes.compile(state)
    live, _ = lanes.collect(unoptimised.copy(state), keys, both, both)
    idled, stats = lanes.collect(unoptimised.copy(state), keys, one_done, one_done)
    assert int(stats.steps[1].sum()) == 0
    jax.tree.map(np.testing.assert_array_equal, lane(idled, 1), lane(state, 1))
    jax.tree.map(np.testing.assert_array_equal, lane(idled, 0), lane(live, 0))


@pytest.mark.slow  # ~4 min per mode on 2 cores: three robots' physics, two lanes
@pytest.mark.parametrize("update", ["sequential", "fused"])
def test_two_lane_sweep_of_a_three_robot_suite_runs_in_both_update_modes(tmp_path, update):
    # XLA:CPU's YNN dot fusion aborts the process on operands of rank 8; ΔQ's vmap over
    # agents under the morphology and lane vmaps made one (the ablations are now a batch
    # axis). A subprocess, since the failure is an abort, with XLA's default flags.
    env = {k: v for k, v in os.environ.items() if k != "XLA_FLAGS"}
    out = tmp_path / "sweep"
    argv = ["morph=hopper++", "net=tiny", "seeds=2", "total_steps=700", f"update={update}"]
    argv += ["td3.warmup_steps=100", "eval_every=0", "checkpoint_every=0", f"out={out}"]
    result = subprocess.run(
        [sys.executable, "-m", "solar_jax.sweep", *argv], env=env, capture_output=True, text=True
    )
    assert result.returncode == 0, result.stderr[-2000:]
    for seed in (0, 1):
        records = read_metrics(out / f"seed{seed}")
        assert records[-1]["kind"] == "eval" and records[-1]["env_steps"] >= 700
