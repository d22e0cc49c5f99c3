"""The runs of one process as lanes of one program: a single run, or a sweep's runs.

The runner (``solar_jax.training.runner``) drives S lanes through one interface, so a
single run and a sweep share every line of the host loop:

    SingleLane(trainer)     S = 1: the trainer's own round, no lane axis (a run's state
                            is its single run's, bit for bit)
    Lanes(trainer, S)       the round vmapped over a leading lane axis of every state
                            leaf ``[S, ...]`` and, when several devices exist, sharded
                            across them (``jax.sharding``, mesh axis ``"lane"``)

Each gives the three pure functions of the round (``episodes``, ``store``, ``train``,
compiled by ``solar_jax.training.programs``), the arguments they take from the host's
per-lane ones (keys ``[S]``, flags ``[S]``, steps), ``place`` (the lanes' states as the
program holds them) and ``lane`` (one lane of a result). Lanes never interact: each
lane's numbers are its single run's (``tests/test_sweep.py``).

A lane that has reached its step budget must stay as it is while the others go on:
``episodes`` runs it ``idle`` (no episode, the state untouched), and ``train`` keeps its
old agent, clustering, key and counters (``live=False``). A single lane is never idle:
the loop ends with it.
"""

import functools

import jax
import jax.numpy as jnp
import numpy as np
from jax.sharding import Mesh, NamedSharding, PartitionSpec

from solar_jax.replay import Replay, append, grow
from solar_jax.training.trainer import RoundStats, Trainer, TrainerState, without_replay

LANE_AXIS = "lane"


def lane_devices(num_lanes: int, devices: list | None = None) -> list:
    """The most devices that split ``num_lanes`` evenly (all lanes on one device if the
    count does not divide)."""
    devices = jax.devices() if devices is None else devices
    count = max(d for d in range(1, len(devices) + 1) if num_lanes % d == 0)
    return devices[:count]


def stack(trees: list):
    """Lane-stacked pytree ``[S, ...]`` of equally shaped pytrees."""
    return jax.tree.map(lambda *leaves: jnp.stack(leaves), *trees)


def lane(tree, index: int):
    """Lane ``index`` of a lane-stacked pytree."""
    return jax.tree.map(lambda leaf: leaf[index], tree)


def _select(live: jax.Array, new, old):
    """Per lane: ``new`` where ``live`` else ``old`` (leaves ``[S, ...]``)."""

    def pick(n, o):
        return jnp.where(live.reshape(live.shape + (1,) * (n.ndim - 1)), n, o)

    return jax.tree.map(pick, new, old)


class SingleLane:
    """One run: the trainer's round as it is (no lane axis)."""

    num_lanes = 1

    def __init__(self, trainer: Trainer):
        self.trainer = trainer
        self.devices = jax.devices()[:1]

    @property
    def fingerprint(self) -> str:
        return self.trainer.fingerprint

    def place(self, states: list[TrainerState]) -> TrainerState:
        (state,) = states
        return state

    def lane(self, tree, index: int):
        return tree

    def grown(self, state: TrainerState) -> TrainerState:
        return self.trainer.grown(state)

    # The round's pure functions and their arguments from the host's per-lane ones.
    def episodes(self, state: TrainerState, eval_key: jax.Array, evaluate: jax.Array):
        return self.trainer.episodes(state, eval_key, evaluate)

    def store(self, replay: Replay, staged: Replay) -> Replay:
        return self.trainer.store(replay, staged)

    def train(self, state: TrainerState, steps: jax.Array) -> tuple[TrainerState, dict]:
        return self.trainer.train(state, steps)

    def episodes_args(self, state, keys, evaluate, idle) -> tuple:
        """``state`` less its replay, lane 0's key ``[2]`` and ``evaluate`` flag (``idle``
        is never set for a single run: the loop ends when it is done)."""
        return without_replay(state), keys[0], jnp.asarray(evaluate[0])

    def train_args(self, state, steps, live) -> tuple:
        return state, steps

    def compile_args(self, state: TrainerState) -> tuple[tuple, tuple, tuple]:
        """Arguments of the three programs shaped as ``state``'s, for compiling."""
        episodes = (without_replay(state), jax.random.PRNGKey(0), jnp.bool_(False))
        steps = jnp.zeros(self.trainer.num_morphs, jnp.int32)
        return episodes, (state.replay, self.trainer.staging()), (state, steps)


class Lanes:
    """``num_lanes`` runs of ``trainer`` vmapped (and sharded):

    episodes(state[S], eval_key[S], evaluate[S], idle[S]) -> (state, RoundStats[S], staged)
    store(replay[S], staged[S])                          -> replay
    train(state[S], steps[S, M], live[S])                -> (state, metrics[S])
    """

    def __init__(self, trainer: Trainer, num_lanes: int, devices: list | None = None):
        self.trainer = trainer
        self.num_lanes = num_lanes
        self.devices = lane_devices(num_lanes, devices)
        mesh = Mesh(np.asarray(self.devices), (LANE_AXIS,))
        self.sharding = NamedSharding(mesh, PartitionSpec(LANE_AXIS))

    @property
    def fingerprint(self) -> str:
        """The trainer's (``Trainer.fingerprint``): the lane count is in the shapes."""
        return self.trainer.fingerprint

    def place(self, states: list[TrainerState]) -> TrainerState:
        """The lanes' states stacked ``[S, ...]`` and split across the devices; replays
        restored at different allocations are grown to the largest (``replay.grow``)."""
        if len(states) != self.num_lanes:
            raise ValueError(f"expected {self.num_lanes} lane states, got {len(states)}")
        slots = max(state.replay.capacity for state in states)
        states = [state.replace(replay=grow(state.replay, slots)) for state in states]
        return jax.device_put(stack(states), self.sharding)

    def lane(self, tree, index: int):
        return lane(tree, index)

    def grown(self, state: TrainerState) -> TrainerState:
        """``Trainer.grown`` for every lane at once, kept on the lanes' devices."""
        grown = self.trainer.grown(state)
        if grown is state:
            return state
        return jax.device_put(grown, self.sharding)

    def _constrain(self, tree):
        if len(self.devices) == 1:
            return tree
        return jax.tree.map(lambda x: jax.lax.with_sharding_constraint(x, self.sharding), tree)

    def episodes(
        self, state: TrainerState, eval_key: jax.Array, evaluate: jax.Array, idle: jax.Array
    ) -> tuple[TrainerState, RoundStats, Replay]:
        state, stats, staged = jax.vmap(self.trainer.episodes)(state, eval_key, evaluate, idle)
        return self._constrain(state), stats, self._constrain(staged)

    def store(self, replay: Replay, staged: Replay) -> Replay:
        return self._constrain(jax.vmap(append)(replay, staged))

    def train(
        self, state: TrainerState, steps: jax.Array, live: jax.Array
    ) -> tuple[TrainerState, dict]:
        train = functools.partial(self.trainer.train, lane_axis=LANE_AXIS)
        new, metrics = jax.vmap(train, axis_name=LANE_AXIS)(state, steps)
        # Training changes only these fields (the replay is collect's).
        kept = _select(
            live,
            (new.agent, new.synergy, new.key, new.updates, new.rounds),
            (state.agent, state.synergy, state.key, state.updates, state.rounds),
        )
        agent, synergy, key, updates, rounds = kept
        new = new.replace(agent=agent, synergy=synergy, key=key, updates=updates, rounds=rounds)
        return self._constrain(new), metrics

    def episodes_args(self, state, keys, evaluate, idle) -> tuple:
        return without_replay(state), keys, jnp.asarray(evaluate), jnp.asarray(idle)

    def train_args(self, state, steps, live) -> tuple:
        """Finished lanes' steps zeroed: they run no iteration."""
        live = jnp.asarray(live)
        return state, jnp.where(live[:, None], steps, 0), live

    def compile_args(self, state: TrainerState) -> tuple[tuple, tuple, tuple]:
        """Arguments of the three programs shaped and placed as ``state``'s."""
        s, m = self.num_lanes, self.trainer.num_morphs
        flags = jnp.zeros(s, bool)
        keys = jax.random.split(jax.random.PRNGKey(0), s)
        staged = jax.tree.map(  # the lanes' staged rounds, as ``episodes`` places them
            lambda x: jax.ShapeDtypeStruct((s, *x.shape), x.dtype, sharding=self.sharding),
            self.trainer.staging(),
        )
        steps = jnp.zeros((s, m), jnp.int32)
        episodes = (without_replay(state), keys, flags, flags)
        return episodes, (state.replay, staged), (state, steps, flags)
