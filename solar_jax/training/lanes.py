"""Many runs of one trainer as one program: the lane axis (seeds × swept scalars).

``SweepTrainer`` vmaps the trainer's two jitted round pieces over a leading lane axis
of ``TrainerState`` (every leaf ``[S, ...]``) and, when several devices exist, shards
that axis across them (``jax.sharding``, mesh axis ``"lane"``). Lanes never interact:
each lane's numbers are its single run's (``tests/test_sweep.py``).

A lane that has reached its step budget must stay as it is while the others go on:
``collect`` runs it as an evaluation (which leaves the state untouched), and ``train``
keeps its old agent, clustering, key and counters (``live=False``).
"""

import jax
import jax.numpy as jnp
import numpy as np
from jax.sharding import Mesh, NamedSharding, PartitionSpec

from solar_jax.compilation_cache import jit_physics
from solar_jax.replay import Replay, append, grow
from solar_jax.training.trainer import (
    RoundStats,
    Trainer,
    TrainerState,
    compile_round,
    without_replay,
)

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


class SweepTrainer:
    """The vmapped (and sharded) round pieces of ``trainer`` for ``num_lanes`` lanes:

    collect(state[S], eval_key[S], evaluate[S], idle[S]) -> (state, RoundStats[S])
    train(state[S], steps[S, M], live[S])       -> (state, metrics[S])

    ``collect`` is the trainer's ``episodes`` program (traced once) then its ``store``
    (traced per replay size, as ``train``; ``traces`` counts them).
    """

    def __init__(self, trainer: Trainer, num_lanes: int, devices: list | None = None):
        self.trainer = trainer
        self.num_lanes = num_lanes
        self.devices = lane_devices(num_lanes, devices)
        mesh = Mesh(np.asarray(self.devices), (LANE_AXIS,))
        self.sharding = NamedSharding(mesh, PartitionSpec(LANE_AXIS))
        self.traces = {"collect": 0, "store": 0, "train": 0}
        self.episodes_program = None  # compiled ahead of time by ``compile``
        self.programs = {}  # replay slots -> (store, train), compiled ahead of time
        self.episodes = jit_physics(self._episodes, donate_argnums=0)  # as compile's
        self.store = jax.jit(self._store, donate_argnums=0)
        self.train = jax.jit(self._train, donate_argnums=0)

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

    def collect(
        self, state: TrainerState, eval_key: jax.Array, evaluate: jax.Array, idle: jax.Array
    ) -> tuple[TrainerState, RoundStats]:
        """Every lane's round (``Trainer.collect``); ``idle`` lanes run no episode."""
        replay = state.replay
        state, stats, staged = self.episodes(without_replay(state), eval_key, evaluate, idle)
        return state.replace(replay=self.store(replay, staged)), stats

    def _episodes(
        self, state: TrainerState, eval_key: jax.Array, evaluate: jax.Array, idle: jax.Array
    ) -> tuple[TrainerState, RoundStats, Replay]:
        self.traces["collect"] += 1
        episodes = jax.vmap(self.trainer._episodes)
        state, stats, staged = episodes(state, eval_key, evaluate, idle)
        return self._constrain(state), stats, self._constrain(staged)

    def _store(self, replay: Replay, staged: Replay) -> Replay:
        self.traces["store"] += 1
        return self._constrain(jax.vmap(append)(replay, staged))

    def _train(
        self, state: TrainerState, steps: jax.Array, live: jax.Array
    ) -> tuple[TrainerState, dict]:
        self.traces["train"] += 1
        new, metrics = jax.vmap(self.trainer._train)(state, steps)
        # Training changes only these fields (the replay is collect's).
        kept = _select(
            live,
            (new.agent, new.synergy, new.key, new.updates, new.rounds),
            (state.agent, state.synergy, state.key, state.updates, state.rounds),
        )
        agent, synergy, key, updates, rounds = kept
        new = new.replace(agent=agent, synergy=synergy, key=key, updates=updates, rounds=rounds)
        return self._constrain(new), metrics

    @property
    def compiled(self) -> bool:
        return bool(self.programs)

    def compile(self, state: TrainerState) -> None:
        """Points ``episodes``, ``store`` and ``train`` at programs compiled ahead of time
        for ``state``'s placement: ``episodes`` once, the other two the first time
        ``state``'s replay size is seen; on one device, through the programs kept on disk
        (``Trainer.compile``)."""
        s, m = self.num_lanes, self.trainer.num_morphs

        def round_args():
            flags = jnp.zeros(s, bool)
            keys = jax.random.split(jax.random.PRNGKey(0), s)
            staged = jax.tree.map(  # the lanes' staged rounds, as _episodes places them
                lambda x: jax.ShapeDtypeStruct((s, *x.shape), x.dtype, sharding=self.sharding),
                self.trainer.staging(),
            )
            steps = jnp.zeros((s, m), jnp.int32)
            episodes = (without_replay(state), keys, flags, flags)
            return episodes, (state.replay, staged), (state, steps, flags)

        programs = compile_round(self, state.replay.capacity, round_args)
        self.episodes, self.store, self.train = programs
