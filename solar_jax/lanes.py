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

from solar_jax.replay import grow
from solar_jax.trainer import RoundStats, Trainer, TrainerState

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

    Each is traced once per replay size (``traces`` counts them).
    """

    def __init__(self, trainer: Trainer, num_lanes: int, devices: list | None = None):
        self.trainer = trainer
        self.num_lanes = num_lanes
        self.devices = lane_devices(num_lanes, devices)
        mesh = Mesh(np.asarray(self.devices), (LANE_AXIS,))
        self.sharding = NamedSharding(mesh, PartitionSpec(LANE_AXIS))
        self.traces = {"collect": 0, "train": 0}
        self.programs = {}  # replay slots -> (collect, train), compiled ahead of time
        self.collect = jax.jit(self._collect, donate_argnums=0)
        self.train = jax.jit(self._train, donate_argnums=0)

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

    def _collect(
        self, state: TrainerState, eval_key: jax.Array, evaluate: jax.Array, idle: jax.Array
    ) -> tuple[TrainerState, RoundStats]:
        self.traces["collect"] += 1
        state, stats = jax.vmap(self.trainer._collect)(state, eval_key, evaluate, idle)
        return self._constrain(state), stats

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
        """Points ``collect`` and ``train`` at the programs for ``state``'s replay size and
        placement, compiled ahead of time the first time that size is seen."""
        slots = state.replay.capacity
        if slots not in self.programs:
            s, m = self.num_lanes, self.trainer.num_morphs
            keys = jax.random.split(jax.random.PRNGKey(0), s)
            flags = jnp.zeros(s, bool)
            steps = jnp.zeros((s, m), jnp.int32)
            collect = jax.jit(self._collect, donate_argnums=0)
            train = jax.jit(self._train, donate_argnums=0)
            self.programs[slots] = (
                collect.lower(state, keys, flags, flags).compile(),
                train.lower(state, steps, flags).compile(),
            )
        self.collect, self.train = self.programs[slots]
