"""The runs of one process as lanes of one program: a single run, or a sweep's runs.

The runner (``solar_jax.training.runner``) drives S lanes through one interface, so a
single run and a sweep share every line of the host loop:

    SingleLane(trainer)     S = 1: the trainer's own round, no lane axis (a run's state
                            is its single run's, bit for bit)
    Lanes(trainer, S)       the round of every lane, each state leaf with a leading lane
                            axis ``[S, ...]`` split across the devices (``shard_map``, mesh
                            axis ``"lane"``); a device's S / D lanes are vmapped, and a
                            device with one lane runs the single run's round on it as it is

Each gives the pure functions of the round (``part_episodes`` of each part of the
collection, ``close``, ``train``, compiled by ``solar_jax.training.programs``), the
arguments they take from the host's per-lane ones (keys ``[S]``, flags ``[S]``, steps),
``place`` (the lanes' states as the program holds them) and ``lane`` (one lane of a
result). Lanes never interact: each lane's numbers are its single run's
(``tests/training/test_sweep.py``).

A lane that has reached its step budget must stay as it is while the others go on:
its parts run ``idle`` (no episode, the state untouched), and ``train`` keeps its old
agent, clustering, key and counters (``live=False``). A single lane is never idle: the
loop ends with it.
"""

import functools

import jax
import jax.numpy as jnp
import numpy as np
from jax.sharding import Mesh, NamedSharding, PartitionSpec

from solar_jax.replay import grow
from solar_jax.training.trainer import Control, Trainer, TrainerState, without_replay

LANE_AXIS = "lane"  # the devices' mesh axis
DEVICE_LANES_AXIS = "device_lanes"  # the vmapped axis of a device's lanes, if several


def lane_devices(num_lanes: int, devices: list | None = None) -> list:
    """The most devices that split ``num_lanes`` evenly (all lanes on one device if the
    count does not divide)."""
    devices = jax.devices() if devices is None else devices
    count = max(d for d in range(1, len(devices) + 1) if num_lanes % d == 0)
    return devices[:count]


# One program for a whole state: eagerly, stacking or slicing compiles a program per leaf
# shape (a tiny two-lane sweep's start: 187 such compiles). They only move data, so on a
# CPU they compile without LLVM's optimisations (the same bits): about 5x less compile,
# copies up to 2x slower (a lane of 340 MB: 107 ms against 52).
COPY_COMPILER_OPTIONS = {"xla_backend_optimization_level": 0}


@functools.cache
def _copy_programs() -> tuple:
    """(stack, lane of arrays), jitted on first use: the backend is known by then."""
    options = COPY_COMPILER_OPTIONS if jax.default_backend() == "cpu" else None

    def stack(trees: list):
        return jax.tree.map(lambda *leaves: jnp.stack(leaves), *trees)

    def lane_of_arrays(tree, index: jax.Array):
        return jax.tree.map(lambda leaf: leaf[index], tree)

    return jax.jit(stack, compiler_options=options), jax.jit(
        lane_of_arrays, compiler_options=options
    )


def stack(trees: list):
    """Lane-stacked pytree ``[S, ...]`` of equally shaped pytrees."""
    return _copy_programs()[0](trees)


def lane(tree, index: int):
    """Lane ``index`` of a lane-stacked pytree (of device arrays, or of host ones: a
    host view stays on the host)."""
    leaves = jax.tree.leaves(tree)
    if leaves and all(isinstance(leaf, jax.Array) for leaf in leaves):
        lanes = leaves[0].shape[0]
        if not -lanes <= index < lanes:  # a traced index would be clamped silently
            raise IndexError(f"lane {index} of {lanes} lanes")
        return _copy_programs()[1](tree, index)
    return jax.tree.map(lambda leaf: leaf[index], tree)


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
    def part_episodes(self, part: int):
        """Part ``part``'s episodes: ``(state, eval_key, control, carry) -> carry``."""
        return functools.partial(self.trainer.part_episodes, part)

    def part_evaluation(self, part: int):
        """Part ``part``'s evaluation (``eval_envs``): ``(state, eval_key) -> (return, length)``."""
        return functools.partial(self.trainer.part_evaluation, part)

    def close(self, state: TrainerState, parts: tuple, evaluate: jax.Array):
        return self.trainer.close(state, parts, evaluate)

    def train(self, state: TrainerState, steps: jax.Array) -> tuple[TrainerState, dict]:
        return self.trainer.train(state, steps)

    def episodes_args(self, state, keys, control: Control) -> tuple:
        """``state`` less its replay, lane 0's key ``[2]`` and control (``idle`` is never
        set for a single run: the loop ends when it is done)."""
        return without_replay(state), keys[0], jax.tree.map(lambda x: x[0], control)

    def evaluation_args(self, state, keys) -> tuple:
        return without_replay(state), keys[0]

    def close_args(self, state, parts, evaluate) -> tuple:
        return state, parts, jnp.asarray(evaluate[0])

    def placed(self, carry):
        return carry

    def train_args(self, state, steps, live) -> tuple:
        return state, steps

    def carries(self) -> list:
        """Each part's round carry, zeros (the first start's input; its values unused)."""
        return [_zeros(shape) for shape in self.trainer.part_shapes]

    def compile_args(self, state: TrainerState) -> tuple[list, tuple, tuple, tuple]:
        """Arguments of the programs shaped as ``state``'s, for compiling: each part's
        episodes, the close, the train and each part's evaluation."""
        control = _control_shapes(())
        carries = self.trainer.part_shapes
        key = jax.random.PRNGKey(0)
        episodes = [(without_replay(state), key, control, carry) for carry in carries]
        close = (state, tuple(carries), jnp.bool_(False))
        steps = jnp.zeros(self.trainer.num_morphs, jnp.int32)
        return episodes, close, (state, steps), (without_replay(state), key)


class Lanes:
    """``num_lanes`` runs of ``trainer``, split across devices:

    part_episodes(p)(state[S], eval_key[S], control[S], carry[S]) -> carry
    close(state[S], carries[S], evaluate[S])                      -> (state, RoundStats[S])
    train(state[S], steps[S, M], live[S])                         -> (state, metrics[S])

    Each program is ``shard_map``'d over the devices (``lane_devices``); a device runs
    its S / D lanes vmapped, or with one lane the single run's function on it (no
    ``vmap``, whose batching rules cost more tracing than the round itself).
    """

    def __init__(self, trainer: Trainer, num_lanes: int, devices: list | None = None):
        self.trainer = trainer
        self.num_lanes = num_lanes
        self.devices = lane_devices(num_lanes, devices)
        self.mesh = Mesh(np.asarray(self.devices), (LANE_AXIS,))
        self.sharding = NamedSharding(self.mesh, PartitionSpec(LANE_AXIS))
        self.device_lanes = num_lanes // len(self.devices)
        # The axes a collective over all lanes names (``Trainer.train``'s ``lane_axis``).
        self.lane_axes = (LANE_AXIS,) if self.device_lanes == 1 else (DEVICE_LANES_AXIS, LANE_AXIS)

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

    def _every_lane(self, fn):
        """``fn`` of one lane's arguments, applied to every lane's (leaves ``[S, ...]``)."""
        if self.device_lanes == 1:

            def on_device(*args):  # [1, ...]: the device's one lane
                out = fn(*jax.tree.map(lambda x: x[0], args))
                return jax.tree.map(lambda x: x[None], out)
        else:
            on_device = jax.vmap(fn, axis_name=DEVICE_LANES_AXIS)
        spec = PartitionSpec(LANE_AXIS)
        # check_vma=False: the round's loops carry values that become per-lane as they go.
        return jax.shard_map(
            on_device, mesh=self.mesh, in_specs=spec, out_specs=spec, check_vma=False
        )

    def part_episodes(self, part: int):
        return self._every_lane(functools.partial(self.trainer.part_episodes, part))

    def part_evaluation(self, part: int):
        return self._every_lane(functools.partial(self.trainer.part_evaluation, part))

    def close(self, state: TrainerState, parts: tuple, evaluate: jax.Array):
        return self._every_lane(self.trainer.close)(state, parts, evaluate)

    def _train_lane(self, state: TrainerState, steps: jax.Array, live: jax.Array):
        new, metrics = self.trainer.train(state, steps, lane_axis=self.lane_axes)
        # Training changes only these fields (the replay is collect's); a finished lane
        # keeps its own.
        kept = jax.tree.map(
            lambda n, o: jnp.where(live, n, o),
            (new.agent, new.synergy, new.key, new.updates, new.rounds),
            (state.agent, state.synergy, state.key, state.updates, state.rounds),
        )
        agent, synergy, key, updates, rounds = kept
        new = new.replace(agent=agent, synergy=synergy, key=key, updates=updates, rounds=rounds)
        return new, metrics

    def train(
        self, state: TrainerState, steps: jax.Array, live: jax.Array
    ) -> tuple[TrainerState, dict]:
        return self._every_lane(self._train_lane)(state, steps, live)

    def episodes_args(self, state, keys, control: Control) -> tuple:
        return without_replay(self._placed_envs(state)), keys, control

    def evaluation_args(self, state, keys) -> tuple:
        return without_replay(self._placed_envs(state)), keys

    def close_args(self, state, parts, evaluate) -> tuple:
        return self._placed_envs(state), self.placed(parts), jnp.asarray(evaluate)

    def placed(self, carry):
        """A part's carry as its program takes it (a program returns its zero-size
        arrays replicated: MJX's empty fields)."""
        return jax.device_put(carry, self.sharding)

    def _placed_envs(self, state: TrainerState) -> TrainerState:
        """``state`` with the environments of rounds of bounded length ``placed``."""
        return state if state.envs is None else state.replace(envs=self.placed(state.envs))

    def train_args(self, state, steps, live) -> tuple:
        """Finished lanes' steps zeroed: they run no iteration."""
        live = jnp.asarray(live)
        return self._placed_envs(state), jnp.where(live[:, None], steps, 0), live

    def _lanes(self, shapes):
        """Per-lane shapes ``[S, ...]`` of one lane's, placed as the lanes' state."""
        s = self.num_lanes
        return jax.tree.map(
            lambda x: jax.ShapeDtypeStruct((s, *x.shape), x.dtype, sharding=self.sharding), shapes
        )

    def carries(self) -> list:
        """Each part's round carry for every lane, zeros (the first start's input)."""
        return [_zeros(self._lanes(shape), self.sharding) for shape in self.trainer.part_shapes]

    def compile_args(self, state: TrainerState) -> tuple[list, tuple, tuple, tuple]:
        """Arguments of the programs shaped and placed as ``state``'s: each part's
        episodes, the close, the train and each part's evaluation."""
        s, m = self.num_lanes, self.trainer.num_morphs
        flags = jnp.zeros(s, bool)
        keys = jax.random.split(jax.random.PRNGKey(0), s)
        control = self._lanes(_control_shapes(()))
        carries = [self._lanes(shape) for shape in self.trainer.part_shapes]
        episodes = [(without_replay(state), keys, control, carry) for carry in carries]
        close = (state, tuple(carries), flags)
        steps = jnp.zeros((s, m), jnp.int32)
        return episodes, close, (state, steps, flags), (without_replay(state), keys)


def _control_shapes(lead: tuple) -> Control:
    """The shapes of a ``Control`` with leading axes ``lead``."""
    flag, step = jax.ShapeDtypeStruct(lead, bool), jax.ShapeDtypeStruct(lead, jnp.int32)
    return Control(evaluate=flag, idle=flag, start=flag, switch=step, until=step)


def _zeros(shapes, sharding=None):
    """Arrays of zeros shaped as ``shapes`` (host-made: no program compiled per leaf shape)."""
    return jax.device_put(jax.tree.map(lambda x: np.zeros(x.shape, x.dtype), shapes), sharding)
