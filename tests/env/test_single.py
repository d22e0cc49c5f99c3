"""One morphology's task: MJX against MuJoCo C, and the rollout tool."""

import dataclasses
import functools
import os
import subprocess
import sys

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
import pytest

from solar_jax.cli import parse_overrides
from solar_jax.config import ConfigError
from solar_jax.env.single import make_env
from solar_jax.morphology import load
from solar_jax.rollout import RolloutConfig
from tests.conftest import REPO
from tests.env.oracle import reference_step
from tests.unoptimised import jit_physics

# float32 MJX against float64 MuJoCo C at the same solver settings (measured with
# benchmarks/drift.py, see benchmarks/README.md). One env step from the same state:
# at most 6e-5 (walker), 6e-4 (humanoid), through contact events. Open loop, contacts
# amplify float32 rounding (chaotic dynamics): within 1e-4 for the first 10 steps, and
# 1e-5 to 9e-2 after 100 steps depending on the robot and the action sequence.
ONE_STEP_ATOL = 1e-3
OPEN_LOOP_ATOL = 1e-1


@functools.cache
def _env(name):
    morph = load(name)
    # No termination, so that both simulators follow one trajectory for 100 steps.
    morph = dataclasses.replace(morph, task=dataclasses.replace(morph.task, terminates=False))
    env = make_env(morph)
    return env, jit_physics(env.reset), jit_physics(env.step)


@pytest.mark.parametrize(
    "name", ["walker_7_main", pytest.param("hopper_5", marks=pytest.mark.slow)]
)  # one robot by default: each compiles its own MJX step (~40 s on CI's 2 cores)
def test_mjx_trajectory_follows_mujoco_c_for_100_steps(name):
    env, reset, step = _env(name)
    morph = env.morph
    model = mujoco.MjModel.from_xml_string(morph.xml)
    model.opt.iterations = env.config.solver_iterations
    model.opt.ls_iterations = env.config.ls_iterations
    state = reset(jax.random.key(0))
    qpos, qvel = np.asarray(state.qpos, np.float64), np.asarray(state.qvel, np.float64)
    actions = np.random.default_rng(0).uniform(-1, 1, (100, morph.num_actuators))
    one_step, open_loop = [], []
    for t in range(100):
        mjx_qpos, mjx_qvel = np.asarray(state.qpos, np.float64), np.asarray(state.qvel, np.float64)
        state = step(state, jnp.asarray(actions[t], jnp.float32))
        # C from MJX's own state: the physics of one step, no accumulated chaos.
        c_qpos, _, c_reward, _ = reference_step(morph, mjx_qpos, mjx_qvel, actions[t], model)
        one_step.append(np.abs(np.asarray(state.qpos) - c_qpos).max())
        assert abs(float(state.reward) - c_reward) < 0.5  # reward = velocity: 1/dt amplifies
        # C open loop from the common start.
        qpos, qvel, _, _ = reference_step(morph, qpos, qvel, actions[t], model)
        open_loop.append(np.abs(np.asarray(state.qpos) - qpos).max())
    assert max(one_step) < ONE_STEP_ATOL, f"one step: {max(one_step):.2e}"
    assert max(open_loop[:10]) < 1e-4  # before contacts, open loop agrees too
    assert max(open_loop) < OPEN_LOOP_ATOL, f"open loop: {max(open_loop):.2e}"


def _rollout(tmp_path, seed, name):
    out = tmp_path / name
    result = subprocess.run(
        [
            sys.executable,
            "-m",
            "solar_jax.rollout",
            "morph=hopper_3",
            "steps=15",
            f"seed={seed}",
            f"out={out}",
        ],
        capture_output=True,
        text=True,
        cwd=REPO,
        timeout=600,
        env={**os.environ, "SOLAR_JAX_CACHE": str(tmp_path / "xla")},
    )
    assert result.returncode == 0, result.stderr
    assert "hopper_3: 15 steps" in result.stdout
    return dict(np.load(out))


@pytest.mark.slow  # ~45 s; tests/training/test_runner.py keeps a subprocess run of train by default
def test_rollout_command_is_deterministic_and_cached(tmp_path):
    first = _rollout(tmp_path, 3, "a.npz")
    assert first["obs"].shape == (15, 3, 19) and first["action"].shape == (15, 2)
    assert first["qpos"].shape == (15, 5)  # 3 root joints + 2 hinges
    assert first["reward"].shape == (15,)
    assert set(first) >= {"qvel", "terminated", "truncated", "agents"}
    assert any((tmp_path / "xla").iterdir())  # compiled once, into the persistent cache
    again, other = _rollout(tmp_path, 3, "b.npz"), _rollout(tmp_path, 4, "c.npz")
    for key in first:
        np.testing.assert_array_equal(first[key], again[key])
    assert not np.array_equal(first["action"], other["action"])


def test_rollout_command_rejects_bad_input():
    result = subprocess.run(
        [sys.executable, "-m", "solar_jax.rollout", "morph=hopper_9"],
        capture_output=True,
        text=True,
        cwd=REPO,
        timeout=120,
    )
    assert result.returncode == 2 and "unknown morphology 'hopper_9'" in result.stderr


def test_overrides_are_typed_and_validated():
    config = parse_overrides(RolloutConfig(), ["steps=7", "env.solver_iterations=9", "morph=x"])
    assert (config.steps, config.env.solver_iterations, config.morph) == (7, 9, "x")
    with pytest.raises(ConfigError, match="unknown config key 'stepz'; did you mean steps\\?"):
        parse_overrides(RolloutConfig(), ["stepz=3"])
    with pytest.raises(ConfigError, match="steps=many: expected int"):
        parse_overrides(RolloutConfig(), ["steps=many"])
    with pytest.raises(ConfigError, match="unknown config key 'env.nope'"):
        parse_overrides(RolloutConfig(), ["env.nope=1"])
    with pytest.raises(ConfigError, match="env.max_episode_steps must be >= 2"):
        parse_overrides(RolloutConfig(), ["env.max_episode_steps=0"])
    with pytest.raises(ConfigError, match="arguments are key=value"):
        parse_overrides(RolloutConfig(), ["steps"])
    flag = parse_overrides(RolloutConfig(), ["env.fix_humanoid_limb_types=true"])
    assert flag.env.fix_humanoid_limb_types is True
