"""The round's collection split into parts (``collect=per_world``: a program per MJX
world): the parts meet where algorithm.md §5 couples the morphologies (the warm-up ends
when the counted steps of all of them reach it; the round ends when the last episode
does), and they collect what one program of all worlds (``collect=joint``) collects.

A suite of two small Euler robots (the tests' hopper, and a copy of it without its
foot, held out), one environment each (the paper's setting), so that their episodes
end at different steps. The parts' programs compile at -O0 (``tests.unoptimised``):
they run a few hundred steps.
"""

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from solar_jax.morphology import suites
from solar_jax.training.lanes import SingleLane
from solar_jax.training.programs import RoundPrograms
from solar_jax.training.trainer import Trainer
from tests import unoptimised
from tests.tiny import CONFIG, ROBOT

WARMUP = 50  # per morphology: 100 counted steps of the two robots
START = 80  # the counted steps before the first round: it crosses the warm-up's end
T_MAX = 60


@pytest.fixture(scope="module")
def pair(tmp_path_factory) -> str:
    """The suite's name, registered for the module: the hopper trains, the footless one
    is held out."""
    xml = ROBOT.read_text()
    foot = xml.index('        <body name="foot"')
    xml = xml[:foot] + xml[xml.index("        </body>", foot) + len("        </body>\n") :]
    xml = xml.replace('    <general name="foot_joint" joint="foot_joint" gear="200"/>\n', "")
    footless = tmp_path_factory.mktemp("robots") / "hopper_2_euler.xml"
    footless.write_text(xml.replace('model="hopper_3"', 'model="hopper_2"'))
    suite = suites.Suite("pair", (str(ROBOT),), (str(footless),))
    suites.SUITES[suite.name] = suite
    yield suite.name
    del suites.SUITES[suite.name]


def _trainer(pair: str, collect: str, layout: str = "per_robot") -> Trainer:
    """``layout``: the pair as two models (two worlds: two parts with ``per_world``), or
    as variants of one union model (the footless hopper embeds in the hopper)."""
    config = dataclasses.replace(
        CONFIG,
        morph=pair,
        num_envs=1,
        collect=collect,
        env=dataclasses.replace(CONFIG.env, max_episode_steps=T_MAX, layout=layout),
        td3=dataclasses.replace(CONFIG.td3, warmup_steps=WARMUP, exploration_noise=0.0),
    )
    return Trainer(config)


def _rounds(trainer: Trainer, state) -> tuple:
    """Two training rounds from ``state`` without exploration noise (the first crosses the
    warm-up's end, the second is the policy's), jitted as they come (no update is
    compiled): the state after them and each round's stats."""
    programs, no, stats = RoundPrograms(SingleLane(trainer)), np.zeros(1, bool), []
    parts = programs._functions[0]
    programs.parts = [unoptimised.jit_physics(part, donate_argnums=3) for part in parts]
    for _ in range(2):
        state, round_stats = programs.collect(state, jax.random.PRNGKey(0)[None], no, no)
        stats.append(jax.device_get(round_stats))
    return jax.device_get(state), stats


def _start(trainer: Trainer):
    state = trainer.init(0)
    return state.replace(env_steps=jnp.int32(START), heldout_steps=jnp.int32(START // 2))


@pytest.fixture(scope="module")
def per_world_trainer(pair) -> Trainer:
    return _trainer(pair, "per_world")


@pytest.fixture(scope="module")
def per_world(per_world_trainer):
    trainer = per_world_trainer
    return (trainer, *_rounds(trainer, _start(trainer)))


def test_a_program_per_world(per_world_trainer, pair):
    trainer = per_world_trainer
    assert [p.morph_ids for p in trainer.parts] == [(0,), (1,)]
    assert [p.world_ids for p in trainer.parts] == [(0,), (1,)]
    assert [p.morph_ids for p in _trainer(pair, "joint").parts] == [(0, 1)]


def test_the_warm_up_switch_by_hand(per_world_trainer):
    trainer = per_world_trainer  # warm-up 2 × 50 counted steps, one environment each, T = 60
    assert trainer.warmup_switch(100) == 0  # past it
    assert trainer.warmup_switch(0) is None  # 2 × 59 steps may reach it: lengths needed
    # At loop step t the round has counted min(t, L1 - 1) + min(t, L2 - 1).
    assert trainer.warmup_switch(0, np.array([[60], [60]])) == 50  # 2t = 100
    assert trainer.warmup_switch(40, np.array([[10], [60]])) == 51  # 40 + 9 + 51 = 100
    assert trainer.warmup_switch(0, np.array([[10], [60]])) == T_MAX  # 9 + 59 < 100


# The rounds below compile two worlds' episodes (about 50 CPU-s): with the default suite
# near its 5 minutes, they run with ``-m slow`` (the tiny runs cover a part alone).
@pytest.mark.slow
def test_the_first_to_finish_steps_on_to_the_last(per_world):
    _, state, stats = per_world
    lengths = [s.episode_length for s in stats]  # [M] per round (one environment each)
    assert any(length[0] != length[1] for length in lengths)
    # Every step of a round is stored for both robots (``replay_continued``): the round
    # lasts as long as the longer episode.
    assert int(state.replay.size[0]) == int(state.replay.size[1])
    assert int(state.replay.size[0]) == sum(int(max(length)) for length in lengths)
    counted = sum(int(s.steps.sum()) for s in stats)
    assert int(state.env_steps) == START + counted
    assert int(state.heldout_steps) == START // 2 + sum(int(s.steps[1]) for s in stats)


@pytest.mark.slow
def test_the_warm_up_ends_where_the_counted_steps_reach_it(per_world):
    trainer, state, stats = per_world
    # The crossing round by hand: at loop step t the robots have counted
    # sum(min(t, L - 1)); uniform actions until START plus that reaches 2 × WARMUP.
    lengths = stats[0].episode_length.astype(int)
    counted = [sum(min(t, length - 1) for length in lengths) for t in range(T_MAX)]
    switch = next(t for t in range(T_MAX) if START + counted[t] >= 2 * WARMUP)
    assert 0 < switch < max(lengths)
    # Without exploration noise, the policy's steps store its deterministic action.
    rows = int(max(lengths))  # the round's steps, one environment each
    replay = state.replay
    for morph in (0, 1):
        ids = np.array([morph])
        obs = jnp.asarray(replay.obs[ids, :rows])  # [1, rows, N, 19]
        policy = trainer.policy(state.agent.actor, obs, state.synergy, ids)[0]
        acting = np.asarray(trainer.networks.acting_mask(trainer.agent_mask))[morph]
        action = np.where(acting, np.clip(np.asarray(policy), -1, 1), 0)
        same = np.all(np.abs(action - replay.action[morph, :rows]) < 1e-5, axis=-1)
        assert not same[:switch].any() and same[switch:].all(), morph


def _assert_same_rounds(split, split_stats, joint, joint_stats):
    """Two layouts' rounds: the same episodes and transitions, up to float rounding."""
    for a, b in zip(split_stats, joint_stats, strict=True):
        np.testing.assert_array_equal(a.steps, b.steps)
        np.testing.assert_array_equal(a.episode_length, b.episode_length)
        np.testing.assert_allclose(a.episode_return, b.episode_return, rtol=1e-5)
    for name in ("env_steps", "heldout_steps", "nonfinite_resets", "key"):
        np.testing.assert_array_equal(getattr(split, name), getattr(joint, name))
    np.testing.assert_array_equal(split.replay.size, joint.replay.size)
    np.testing.assert_array_equal(split.replay.terminated, joint.replay.terminated)
    for name in ("obs", "action", "reward", "next_obs"):
        a, b = getattr(split.replay, name), getattr(joint.replay, name)
        np.testing.assert_allclose(a, b, atol=1e-5, err_msg=name)


@pytest.mark.slow  # 35 s more: the joint layout's two-world program too
def test_parts_collect_what_one_program_collects(per_world, pair):
    trainer, split, split_stats = per_world
    _assert_same_rounds(split, split_stats, *_rounds(_trainer(pair, "joint"), _start(trainer)))


@pytest.mark.slow  # 25 s more: the union's program
def test_a_union_collects_what_a_model_per_robot_collects(per_world, pair):
    trainer, split, split_stats = per_world
    union = _trainer(pair, "joint", layout="union")
    assert len(union.env.worlds) == 1 and union.env.unions[0] is not None
    _assert_same_rounds(split, split_stats, *_rounds(union, _start(trainer)))
