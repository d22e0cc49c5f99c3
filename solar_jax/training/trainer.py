"""The paper's training round, jitted end to end (algorithm.md §3 and §5).

A round (algorithm.md §5): every morphology (held-out ones too) resets and steps until
each of its environments has finished one episode; environments that finished keep
stepping after their auto-reset, and (as the reference) those transitions are stored but
not counted. An episode of L steps counts L - 1. Rounds of bounded length
(``round_steps``, beyond the paper) step every environment that many times instead,
going on from where the last round left them (``TrainerState.envs``), and store every
transition; a step still counts unless an episode ended on it. Then
``per_morph_iters = (counted steps of all morphologies) // (M_all × td3.update_every)``
TD3 iterations per training morphology (the paper's ``update_every`` is 1); before
them ΔQ → affinity propagation re-clusters: in ``update=sequential`` each morphology
just before its own block, in sorted-name order (held-out ones too, with no block of their own), as
the reference; in ``update=fused`` every morphology once. ``Trainer`` holds what a
config builds (env, networks, TD3, clustering) and the pure functions of the round,
jitted elsewhere (``solar_jax.training.programs``, through ``solar_jax.training.lanes``
for one run or many):

    part_episodes(p, state less replay, eval_key, control, carry) -> carry
        while_loop over part p's env steps; compiled once per part: it never sees
        the replay's size
    close(state, carries, evaluate) -> (state, RoundStats)
        the parts' staged transitions appended to the ring, the steps counted
    train(state, steps) -> (state, dict)   clustering + update loops

The collection is split into parts (``collection_parts``: the MJX worlds, each its own
program, or all in one), which never read each other's state: they share the actor
and the round's keys (each draws the suite's noise and keeps its rows), and meet only
where the round couples them, decided on the host between calls (``Control``): a round
ends when the last environment of any part has finished (parts that finished first step
on to it, ``until``), and the warm-up ends at the loop step where the counted steps of
all parts reach it (``switch``; ``warmup_switch``: the round that crosses it is first
run at random throughout for its episodes' lengths). The round is staged in a ring of
its own, ``num_envs × max_episode_steps`` slots per morphology (all a round can write),
so the programs with the physics, the costly ones to compile, are compiled once per run
and not again each time the replay grows (``replay_slots``); ``close`` and ``train``
are compiled per replay size. ``evaluate=True`` (traced, so the physics compiles once)
runs the deterministic policy from ``eval_key`` and leaves the state as it was. Python
runs only between these calls (``solar_jax.training.programs``, the round's host side;
``solar_jax.training.runner``: logging, evaluation, checkpoints).
"""

import functools
import json
import os

import jax
import jax.numpy as jnp
import numpy as np
from flax import struct

from solar_jax.agent import AgentState, Hyper, make_td3, with_learning_rates
from solar_jax.config import TD3Config, TrainConfig, config_to_dict
from solar_jax.env.batch import MultiEnv, MultiState
from solar_jax.env.world import OBS_SIZE, model_bytes
from solar_jax.morphology import get_suite
from solar_jax.networks import Structure, limb_trees, make_networks, pad_traversal
from solar_jax.replay import (
    Batch,
    Replay,
    add,
    append,
    grow,
    init_replay,
    sample,
    sample_each,
)
from solar_jax.synergy import Synergy, delta_q_preference, slot_bucket, slot_buckets
from solar_jax.synergy.discovery import SuiteAffinity
from solar_jax.training.rundir import BOOKKEEPING
from solar_jax.xla.cache import program_fingerprint
from solar_jax.xla.programs import jit_init, jit_start

REFERENCE_CAPACITY = 1_000_000  # per morphology (algorithm.md §5)
SATURATED = 0.99  # |a| above this counts as a saturated action (the diagnostics)
LaneAxis = str | tuple[str, ...] | None  # a sweep's lane axis name(s), None for a single run
REFERENCE_TOTAL = 10_000_000  # split over morphologies when there are more than 10
NOISE_SCALE_STREAM = 0x5CA1E  # folded into a round's key for its per-environment noise stds


@struct.dataclass
class TrainerState:
    """Everything a run needs to continue bit for bit (what a checkpoint holds)."""

    agent: AgentState
    replay: Replay
    synergy: Synergy  # [M] the current clustering of every morphology
    hyper: Hyper
    key: jax.Array  # uint32 [2]
    env_steps: jax.Array  # int32: counted env steps of all morphologies (the reference's)
    heldout_steps: jax.Array  # int32: the held-out morphologies' part of env_steps
    updates: jax.Array  # int32: TD3 iterations (critic steps)
    rounds: jax.Array  # int32
    nonfinite_resets: jax.Array  # [M] int32: physics blow-ups, reset and not stored
    envs: "Continuing | None" = None  # rounds of bounded length: the environments between


@struct.dataclass
class Continuing:
    """The environments between rounds of bounded length (``round_steps``), mid-episode."""

    worlds: tuple  # every world's WorldState, batched over B, in the env's world order
    started: jax.Array  # bool []: reset by a first round (before it, blank)
    last_return: jax.Array  # [M, B] each environment's latest finished episode's return
    last_length: jax.Array  # [M, B] its length L; 0: none finished yet
    noise_scale: jax.Array  # [M, B] each environment's exploration std, drawn per episode

    def latest(self) -> tuple[jax.Array, jax.Array]:
        """``[M]`` each robot's mean latest episode return and length over its
        environments that have finished one (0 where none has)."""
        finished = self.last_length > 0
        count = jnp.maximum(finished.sum(axis=1), 1)
        return tuple(
            jnp.where(finished, x, 0.0).sum(axis=1) / count
            for x in (self.last_return, self.last_length)
        )


def without_replay(state: TrainerState) -> TrainerState:
    """``state`` less its replay (``None``), the input of the parts' episode programs, so
    that they do not depend on the replay's size."""
    return state.replace(replay=None)


@struct.dataclass
class Control:
    """What the host decides for one call of a part's episodes (``Trainer.part_episodes``),
    per lane: scalars."""

    evaluate: jax.Array  # bool: deterministic policy, nothing stored or counted
    idle: jax.Array  # bool: no episode at all (a sweep's finished lane)
    start: jax.Array  # bool: a fresh round (reset), else go on from the carry
    switch: jax.Array  # int32: uniform random actions at loop steps before it (warm-up)
    until: jax.Array  # int32: step on to this loop step even when every episode has ended


@struct.dataclass
class PartRound:
    """A part's round in progress, per robot ``[R, ...]`` of the part."""

    env: MultiState
    staged: Replay  # [R, B × max_episode_steps, ...] the round's transitions so far
    active: jax.Array  # [R, B] bool: still in the round's (first) episode
    ret: jax.Array  # [R, B] that episode's return, once ended
    length: jax.Array  # [R, B] its length L, once ended
    steps: jax.Array  # [R] int32 counted steps (L - 1 per episode)
    episodes: jax.Array  # [R] int32 episodes ended in the round
    nonfinite: jax.Array  # [R] int32 physics blow-ups
    scale: jax.Array | None  # [R, B] rounds of bounded length: each env's exploration std
    t: jax.Array  # int32 loop steps so far
    key: jax.Array  # the loop's key


@struct.dataclass
class RoundStats:
    """One collection round, per morphology ``[M]``: the first episode of each env (in
    rounds of bounded length, each env's latest finished one; 0 before any)."""

    episode_return: jax.Array  # mean over the morphology's environments
    episode_length: jax.Array  # L, the steps of the episode (it counts L - 1)
    steps: jax.Array  # int32: counted steps (every env's first episode, L - 1 each)
    episodes: jax.Array  # int32: episodes that ended in the round


def check_masks(names: tuple[str, ...], env_mask: np.ndarray, synergy_mask: np.ndarray) -> None:
    """The env's agent masks ``[M, N_max]`` (from its MJX worlds) and the synergy
    structure's (from the morphologies' parents) must mark the same agents: the networks
    read one, the clustering the other. One error line naming the first robot that
    differs."""
    if env_mask.shape != synergy_mask.shape:
        raise ValueError(f"agent masks: env {env_mask.shape}, synergy {synergy_mask.shape}")
    for name, env_row, synergy_row in zip(names, env_mask, synergy_mask, strict=True):
        if not np.array_equal(env_row, synergy_row):
            raise ValueError(
                f"{name}: the env's agent mask {env_row.astype(int).tolist()} is not the "
                f"synergy structure's {synergy_row.astype(int).tolist()}"
            )


def replay_capacity(config: TrainConfig, num_morphs: int) -> int:
    """Per-morphology ring size: ``config.replay_capacity``, else the reference's rule
    (1e6, or 1e7 / M_all with more than 10 morphologies, held-out ones included)."""
    if config.replay_capacity:
        return config.replay_capacity
    return REFERENCE_CAPACITY if num_morphs <= 10 else REFERENCE_TOTAL // num_morphs


PER_WORLD_MIN_CPUS = 4
"""``collect=auto`` compiles a program per world on a CPU host with at least this many
cores. On 2 cores a program per world costs about 1.5x the CPU of one program (whh++'s
first 8 robots, the whole round: 342 CPU-s and 176 s wall against 231 and 141;
benchmarks/README.md, ``compile.py``), so there it starts later; it then collects
1.4x faster (humanoid++, ``training.py``), repaying the compile after about 75k counted
steps. Where the compile itself starts to pay is not measured yet; 4 cores is the least
at which the compiles can overlap enough to repay 1.5x."""


def collection_parts(config: TrainConfig, env: MultiEnv) -> list[list[int]]:
    """The worlds of each program of a round's collection (``config.collect``): ``joint``,
    every world in one program; ``per_world``, a program per world (compiled side by
    side); ``auto``: per world on an accelerator or a CPU host of ``PER_WORLD_MIN_CPUS``
    cores or more, else joint."""
    worlds = list(range(len(env.worlds)))
    layout = config.collect
    if layout == "auto":
        many_cores = (os.cpu_count() or 1) >= PER_WORLD_MIN_CPUS
        layout = "per_world" if jax.default_backend() != "cpu" or many_cores else "joint"
    return [[w] for w in worlds] if layout == "per_world" else [worlds]


def round_length(config: TrainConfig) -> int:
    """The most steps a training round takes per environment: ``round_steps``, or in
    episode rounds the time limit."""
    return config.round_steps or config.env.max_episode_steps


def replay_slots(config: TrainConfig, num_morphs: int, size: int) -> int:
    """The slots to allocate before a round, for buffers holding ``size`` transitions
    (the fullest morphology's).

    The reference's ring is allocated as it fills, on a ladder of powers of two from
    twice one round's most writes (``num_envs × round_length`` per morphology),
    so that no round can fill it; it wraps only at its full size. Until then the
    transitions sit where a full-size ring would keep them and sampling reads only
    filled slots, so results are those of the full ring, whatever ``total_steps`` is
    and however often a run is resumed. An explicit ``replay_capacity`` is allocated
    whole."""
    ring = replay_capacity(config, num_morphs)
    if config.replay_capacity:
        return ring
    headroom = config.num_envs * round_length(config)
    slots = 1 << (2 * headroom - 1).bit_length()  # the first power of two >= 2 · headroom
    while slots <= size + headroom and slots < ring:
        slots *= 2
    return min(slots, ring)


class Trainer:
    """Builds the env, networks, TD3 and replay of a config; its jitted round pieces."""

    def __init__(self, config: TrainConfig, env: MultiEnv | None = None):
        suite = get_suite(config.morph)
        self.config = config
        self.env = env or MultiEnv(suite.members, config.num_envs, config.env)
        members = tuple(m.loaded_from for m in self.env.morphs)
        if members != suite.members or self.env.batch_size != config.num_envs:
            raise ValueError("the given env does not match the config's suite and num_envs")
        self.names = self.env.names
        # The round's collection: one program per part (``collection_parts``).
        self.parts = [self.env.part(worlds) for worlds in collection_parts(config, self.env)]
        # Evaluations with their own environments (``eval_envs``): a program per part too.
        self.eval_parts = []
        if config.eval_envs:
            env = self.env.with_batch_size(config.eval_envs)
            self.eval_parts = [env.part(worlds) for worlds in collection_parts(config, env)]
        self._suite_order = np.argsort(np.concatenate([p.morph_ids for p in self.parts]))
        self.num_train = len(suite.train)
        self.num_morphs = self.env.num_morphs
        n_max, morphs = self.env.n_max, self.env.morphs
        trees = limb_trees([m.parents for m in morphs], [m.name for m in morphs], n_max)
        self.tree, self.max_children = trees
        self.networks = make_networks(
            config.method, config.network, n_max, OBS_SIZE, self.max_children
        )
        self.td3 = make_td3(self.networks, config.td3)
        self.affinity = SuiteAffinity([m.parents for m in morphs], n_max)
        check_masks(self.names, self.env.agent_mask, self.affinity.mask)
        self.agent_mask = jnp.asarray(self.env.agent_mask)
        self.traversal = jnp.stack([pad_traversal(m.traversal, n_max) for m in morphs])
        self.capacity = replay_capacity(config, self.num_morphs)  # the ring's full size
        # The sequential update's morphology order: sorted names, held-out ones included.
        self.update_order = jnp.asarray(np.argsort(self.names, kind="stable"), jnp.int32)

    @functools.cached_property
    def fingerprint(self) -> str:
        """What the round's programs are traced from, hashed (``compile_program``): the
        config less its bookkeeping keys, the env's settings and its MuJoCo models."""
        fields = {k: v for k, v in config_to_dict(self.config).items() if k not in BOOKKEEPING}
        settings = json.dumps([fields, config_to_dict(self.env.config)], sort_keys=True)
        return program_fingerprint(settings, *(model_bytes(m) for m in self.env.models()))

    def staging(self) -> Replay:
        """The shapes of a round's staged transitions of every morphology (``close``)."""
        slots = self._staging_slots
        return jax.eval_shape(lambda: init_replay(self.num_morphs, slots, self.env.n_max, OBS_SIZE))

    def grown(self, state: "TrainerState") -> "TrainerState":
        """``state`` with the replay slots its next round needs (``replay_slots``; also for
        lane-stacked states, by the fullest buffer of any lane)."""
        size = int(jnp.max(state.replay.size))
        slots = replay_slots(self.config, self.num_morphs, size)
        if slots <= state.replay.capacity:
            return state
        return state.replace(replay=grow(state.replay, slots))

    # ----------------------------------------------------------------------------- state
    @functools.cached_property
    def _init_agent(self):
        """The TD3 state's initialisation, jitted once per trainer (eager Flax init: 2x
        slower; a new ``jax.jit`` per ``init`` would trace it again every time), kept
        on disk under the trainer's fingerprint (``jit_start``)."""
        return jit_init(self.td3.init, self.fingerprint)

    @functools.cached_property
    def _first_clustering(self):
        """The median preference's clustering, jitted once per trainer (likewise)."""
        return jit_start(self.affinity.cluster, self.fingerprint)

    def init(self, seed: int, td3: TD3Config | None = None, slots: int = 0) -> TrainerState:
        """A fresh run. ``td3``: a sweep lane's scalar hyper-parameters (learning rates,
        γ, τ, noises) in place of the config's; the static ones must be the config's.
        ``slots``: the replay's allocation (0: a fresh run's first, ``replay_slots``)."""
        slots = slots or replay_slots(self.config, self.num_morphs, 0)
        envs = None
        if self.config.round_steps:  # blank until the first round resets them
            shape = (self.num_morphs, self.env.batch_size)
            worlds = jax.eval_shape(self.env.blank, jax.random.PRNGKey(0)).worlds
            envs = Continuing(
                worlds=jax.tree.map(lambda x: np.zeros(x.shape, x.dtype), worlds),
                started=np.bool_(False),
                last_return=np.zeros(shape, np.float32),
                last_length=np.zeros(shape, np.float32),
                noise_scale=np.zeros(shape, np.float32),
            )
        key = jax.random.PRNGKey(seed)
        key, agent_key = jax.random.split(key)
        agent = self._init_agent(agent_key)
        if td3 is not None:
            agent = with_learning_rates(agent, td3)
        return TrainerState(
            agent=agent,
            replay=init_replay(self.num_morphs, slots, self.env.n_max, OBS_SIZE),
            synergy=self._first_clustering(),  # the median preference first
            hyper=Hyper.from_config(td3 or self.config.td3),
            key=key,
            env_steps=jnp.int32(0),
            heldout_steps=jnp.int32(0),
            updates=jnp.int32(0),
            rounds=jnp.int32(0),
            nonfinite_resets=jnp.zeros(self.num_morphs, jnp.int32),
            envs=envs,
        )

    def structure(self, synergy: Synergy) -> Structure:
        """Every morphology's network inputs, ``[M, ...]``."""
        return Structure(self.agent_mask, synergy, self.traversal, self.tree)

    def policy(self, actor, obs: jax.Array, synergy: Synergy, ids: np.ndarray) -> jax.Array:
        """Deterministic actions ``[R, B, N]`` for observations ``[R, B, N, 19]`` of the
        suite's robots ``ids [R]`` (``synergy``: every morphology's, ``[M]``)."""
        act = jax.vmap(self.networks.act, in_axes=(None, 0, 0, 0, 0, 0))
        synergy, tree = jax.tree.map(lambda x: x[ids], (synergy, self.tree))
        return act(actor, obs, self.agent_mask[ids], synergy, self.traversal[ids], tree)

    # --------------------------------------------------------------------------- collect
    def part_start(
        self,
        part: int,
        key: jax.Array,
        eval_key,
        control: Control,
        envs: Continuing | None = None,
        high: jax.Array | float = 0.0,
        blank: bool = False,
    ) -> PartRound:
        """Part ``part``'s round before its first step (``key``: the state's): its
        environments reset (in rounds of bounded length, ``envs``, where the last round
        left them, unless evaluating or before the first), nothing staged, every
        environment active unless the lane is ``idle``; in rounds of bounded length each
        environment's exploration std (``high``: the largest) as the last round left it,
        or drawn. ``blank``: the same shapes, the environments not reset
        (``part_shapes``)."""
        env = self.parts[part]
        reset_key, loop_key = self._round_keys(key, eval_key, control.evaluate)
        shape = (env.num_morphs, env.batch_size)
        zeros = jnp.zeros(shape, jnp.float32)
        ids = np.asarray(env.morph_ids)
        scale = None
        if blank:
            env_state = env.blank(reset_key)
            scale = zeros if self.config.round_steps else None
        elif envs is None:
            env_state = env.reset(reset_key, control.evaluate)
        else:
            fresh = control.evaluate | ~envs.started
            env_state = jax.lax.cond(
                fresh,
                lambda: env.reset(reset_key, control.evaluate),
                lambda: env.going_on([envs.worlds[w] for w in env.world_ids]),
            )
            first = self._noise_scales(jax.random.fold_in(key, NOISE_SCALE_STREAM), ids, high)
            scale = jnp.where(fresh, first, envs.noise_scale[ids])
        return PartRound(
            env=env_state,
            staged=init_replay(env.num_morphs, self._staging_slots, env.n_max, OBS_SIZE),
            active=jnp.broadcast_to(~jnp.asarray(control.idle), shape),
            ret=zeros,
            length=zeros,
            steps=jnp.zeros(env.num_morphs, jnp.int32),
            episodes=jnp.zeros(env.num_morphs, jnp.int32),
            nonfinite=jnp.zeros(env.num_morphs, jnp.int32),
            scale=scale,
            t=jnp.int32(0),
            key=loop_key,
        )

    @functools.cached_property
    def part_shapes(self) -> list[PartRound]:
        """Each part's ``PartRound`` shapes (no MJX traced: ``MultiEnv.blank``)."""
        key = jax.ShapeDtypeStruct((2,), jnp.uint32)
        flag, step = jax.ShapeDtypeStruct((), bool), jax.ShapeDtypeStruct((), jnp.int32)
        control = Control(evaluate=flag, idle=flag, start=flag, switch=step, until=step)
        return [
            jax.eval_shape(functools.partial(self.part_start, p, blank=True), key, key, control)
            for p in range(len(self.parts))
        ]

    @staticmethod
    def _round_keys(key: jax.Array, eval_key, evaluate) -> tuple[jax.Array, jax.Array]:
        """(reset key, loop key) of a round: from the state's ``key``, or ``eval_key`` when
        evaluating (``close`` advances the state's key past the round)."""
        _, round_key = jax.random.split(key)
        reset_key, loop_key = jax.random.split(jnp.where(evaluate, eval_key, round_key))
        return reset_key, loop_key

    @property
    def _staging_slots(self) -> int:
        """A round's staging ring per morphology: every step writes at most B rows and a
        training round has at most ``round_length`` steps, so it never wraps (an
        evaluation stages nothing)."""
        return self.env.batch_size * round_length(self.config)

    def part_episodes(
        self,
        part: int,
        state: TrainerState,
        eval_key: jax.Array,
        control: Control,
        carry: PartRound,
    ) -> PartRound:
        """Steps part ``part``'s environments (``state`` less its replay, ``without_replay``):
        from a fresh start (``control.start``, the carry's values unused) or from ``carry``,
        while any of its environments is in its round's episode or the loop is short of
        ``control.until``, and at most ``max_episode_steps`` steps; in rounds of bounded
        length (``round_steps``), a training round steps ``round_steps`` times, every
        environment staying in the round across its episodes' ends. Uniform random actions
        at loop steps before ``control.switch`` (the warm-up's end, ``warmup_switch``), the
        policy with exploration noise after, the deterministic policy when evaluating
        (nothing stored or counted). Transitions are staged in the carry's ring."""
        env = self.parts[part]
        ids = np.asarray(env.morph_ids)  # the part's robots in the suite
        m, b, n = self.num_morphs, env.batch_size, env.n_max
        evaluate = control.evaluate
        acting = self.networks.acting_mask(self.agent_mask)[ids][:, None, :]  # [R, 1, N]
        continued = self.config.replay_continued
        bounded = self.config.round_steps > 0
        high = state.hyper.exploration_noise
        scale = None if bounded else self._exploration_scale(state, ids)  # [R, B, 1] or []
        # Rounds of bounded length: training rounds never leave their environments.
        going_on = bounded & ~evaluate & ~control.idle
        limit = jnp.where(going_on, self.config.round_steps, self.config.env.max_episode_steps)

        def act(obs, key, t, scale):
            noise_key, uniform_key = jax.random.split(key)

            # Noise and uniform draws for the whole suite [M, B, N], then the part's rows:
            # the numbers a round of all parts in one program draws.
            def explore(_):
                action = self.policy(state.agent.actor, obs, state.synergy, ids)
                noise = jax.random.normal(noise_key, (m, b, n))[ids]
                return action + jnp.where(evaluate, 0.0, scale * noise)

            def uniform(_):
                return jax.random.uniform(uniform_key, (m, b, n), minval=-1.0, maxval=1.0)[ids]

            random = ~evaluate & (t < control.switch)
            action = jax.lax.cond(random, uniform, explore, None)
            return jnp.where(acting, jnp.clip(action, -1.0, 1.0), 0.0)

        def body(c: PartRound) -> PartRound:
            if bounded:  # each environment's std drawn anew when its episode ends
                key, act_key, scale_key = jax.random.split(c.key, 3)
                step_scale = c.scale[..., None]
            else:
                (key, act_key), step_scale = jax.random.split(c.key), scale
            env_state, tr = env.step(c.env, act(c.env.obs, act_key, c.t, step_scale))
            # Finished environments step on after their auto-reset; the reference stores
            # those transitions too (``replay_continued``) but does not count them.
            record = (c.active | continued) & tr.valid & ~evaluate
            batch = Batch(tr.obs, tr.action, tr.reward, tr.next_obs, tr.terminated)
            ended = c.active & tr.done
            # The reference counts a step unless the episode ended on it: L - 1 per episode.
            counted = (c.active & ~tr.done).sum(axis=1, dtype=jnp.int32)
            return PartRound(
                env=env_state,
                staged=add(c.staged, batch, record),
                active=c.active & (~tr.done | going_on),
                ret=jnp.where(ended, tr.episode_return, c.ret),
                length=jnp.where(ended, tr.episode_length, c.length),
                steps=c.steps + counted,
                episodes=c.episodes + ended.sum(axis=1, dtype=jnp.int32),
                nonfinite=c.nonfinite + (~tr.valid).sum(axis=1, dtype=jnp.int32),
                scale=jnp.where(tr.done, self._noise_scales(scale_key, ids, high), c.scale)
                if bounded
                else None,
                t=c.t + 1,
                key=key,
            )

        def cond(c: PartRound):
            going = jnp.any(c.active) | (c.t < control.until)
            return going & (c.t < limit)

        carry = jax.lax.cond(
            control.start,
            lambda carry: self.part_start(part, state.key, eval_key, control, state.envs, high),
            lambda carry: carry,
            carry,
        )
        return jax.lax.while_loop(cond, body, carry)

    def part_evaluation(
        self, part: int, state: TrainerState, eval_key: jax.Array
    ) -> tuple[jax.Array, jax.Array]:
        """(return, length) ``[R, eval_envs]`` of a deterministic episode of each of part
        ``part``'s evaluation environments (``eval_parts``; ``state`` less its replay),
        reset as the nominal robots from ``eval_key`` as the collection's evaluation is."""
        env = self.eval_parts[part]
        ids = np.asarray(env.morph_ids)
        acting = self.networks.acting_mask(self.agent_mask)[ids][:, None, :]  # [R, 1, N]
        reset_key, _ = self._round_keys(state.key, eval_key, jnp.bool_(True))
        shape = (env.num_morphs, env.batch_size)

        def body(c):
            env_state, active, ret, length, t = c
            action = self.policy(state.agent.actor, env_state.obs, state.synergy, ids)
            env_state, tr = env.step(env_state, jnp.where(acting, jnp.clip(action, -1, 1), 0.0))
            ended = active & tr.done
            ret = jnp.where(ended, tr.episode_return, ret)
            length = jnp.where(ended, tr.episode_length, length)
            return env_state, active & ~tr.done, ret, length, t + 1

        def cond(c):
            return jnp.any(c[1]) & (c[4] < self.config.env.max_episode_steps)

        zeros = jnp.zeros(shape, jnp.float32)
        start = (env.reset(reset_key, True), jnp.ones(shape, bool), zeros, zeros, jnp.int32(0))
        _, _, ret, length, _ = jax.lax.while_loop(cond, body, start)
        return ret, length

    def _exploration_scale(self, state: TrainerState, ids: np.ndarray) -> jax.Array:
        """An episode round's exploration noise std: ``hyper.exploration_noise`` [], or
        with ``td3.exploration_noise_min`` one per environment of the round, drawn for the
        whole suite [M, B] from the round's key and cut to the part's robots [R, B, 1]."""
        high = state.hyper.exploration_noise
        if self.config.td3.exploration_noise_min is None:
            return high
        key = jax.random.fold_in(state.key, NOISE_SCALE_STREAM)
        return self._noise_scales(key, ids, high)[..., None]

    def _noise_scales(self, key: jax.Array, ids: np.ndarray, high) -> jax.Array:
        """Exploration stds ``[R, B]`` of robots ``ids``: ``high``, or with
        ``td3.exploration_noise_min`` uniform in [min, ``high``], drawn for the whole suite
        ``[M, B]`` from ``key`` (so every part draws the numbers of one program of all)."""
        low = self.config.td3.exploration_noise_min
        shape = (self.num_morphs, self.env.batch_size)
        if low is None:
            return jnp.full(shape, high, jnp.float32)[ids]
        return (low + (high - low) * jax.random.uniform(key, shape))[ids]

    def warmup_switch(self, env_steps: int, lengths: np.ndarray | None = None) -> int | None:
        """The loop step at which a training round starting at ``env_steps`` counted steps
        stops acting uniformly at random (algorithm.md §5: the first ``warmup_steps`` × M_all
        counted steps of all morphologies), on the host: 0 past the warm-up,
        ``max_episode_steps`` when the round cannot reach its end. The one round that may
        cross it needs its episodes' lengths ``lengths [M, B]`` from a round run at random
        throughout (the same until that step; None: not given yet). At loop step t the
        round has counted sum(min(t, L - 1)) steps (an episode of L steps counts its first
        L - 1), so the switch is the first t at which ``env_steps`` plus those reach the
        warm-up. In rounds of bounded length, a round starting short of the warm-up is
        random throughout (``round_steps``)."""
        warmup = self.config.td3.warmup_steps * self.num_morphs
        limit = self.config.env.max_episode_steps
        if env_steps >= warmup:
            return 0
        if self.config.round_steps:
            return self.config.round_steps
        if env_steps + self.num_morphs * self.env.batch_size * (limit - 1) < warmup:
            return limit
        if lengths is None:
            return None
        t = np.arange(limit)[:, None]
        counted = np.minimum(t, np.maximum(np.ravel(lengths)[None, :] - 1, 0)).sum(axis=1)
        reached = np.flatnonzero(env_steps + counted >= warmup)
        return int(reached[0]) if reached.size else limit

    def close(
        self, state: TrainerState, parts: tuple[PartRound, ...], evaluate: jax.Array
    ) -> tuple[TrainerState, RoundStats]:
        """The round's end: the parts' staged transitions appended to ``state``'s replay
        (``replay.append``: as if written step by step), its counted steps, physics
        blow-ups and key advanced, the environments kept for the next round of bounded
        length (evaluation leaves the state as it was), and its stats."""

        def suite(field: str) -> jax.Array:  # [M, ...] in suite order
            return jnp.concatenate([getattr(p, field) for p in parts])[self._suite_order]

        staged = jax.tree.map(
            lambda *x: jnp.concatenate(x)[self._suite_order], *[p.staged for p in parts]
        )
        steps, nonfinite = suite("steps"), suite("nonfinite")
        is_train = jnp.arange(self.num_morphs) < self.num_train
        next_key, _ = jax.random.split(state.key)

        def keep(old, new):  # evaluation leaves the state as it was
            return jnp.where(evaluate, old, new)

        ret, length = suite("ret"), suite("length")  # [M, B]
        episode_return, episode_length = ret.mean(axis=1), length.mean(axis=1)
        envs = state.envs
        if envs is not None:
            going = self._going_on(envs, parts, ret, length)
            latest_return, latest_length = going.latest()  # a training round's stats
            episode_return = jnp.where(evaluate, episode_return, latest_return)
            episode_length = jnp.where(evaluate, episode_length, latest_length)
            envs = jax.tree.map(keep, envs, going)
        state = state.replace(
            envs=envs,
            replay=append(state.replay, staged),  # nothing is staged when evaluating
            key=keep(state.key, next_key),
            env_steps=keep(state.env_steps, state.env_steps + jnp.sum(steps)),
            heldout_steps=keep(
                state.heldout_steps, state.heldout_steps + jnp.sum(steps * ~is_train)
            ),
            nonfinite_resets=keep(state.nonfinite_resets, state.nonfinite_resets + nonfinite),
        )
        stats = RoundStats(
            episode_return=episode_return,
            episode_length=episode_length,
            steps=steps,
            episodes=suite("episodes"),
        )
        return state, stats

    def _going_on(
        self, envs: Continuing, parts: tuple[PartRound, ...], ret: jax.Array, length: jax.Array
    ) -> Continuing:
        """``envs`` after a training round of bounded length: the parts' environments as
        it left them, and the episodes that ended in it (``ret``, ``length`` ``[M, B]``,
        0 where none did)."""
        worlds = list(envs.worlds)
        for carry, env in zip(parts, self.parts, strict=True):
            for w, world in zip(env.world_ids, carry.env.worlds, strict=True):
                worlds[w] = world
        ended = length > 0
        scale = jnp.concatenate([p.scale for p in parts])[self._suite_order]
        return Continuing(
            worlds=tuple(worlds),
            started=jnp.bool_(True),
            last_return=jnp.where(ended, ret, envs.last_return),
            last_length=jnp.where(ended, length, envs.last_length),
            noise_scale=scale,
        )

    # ----------------------------------------------------------------------------- train
    def _reclusters(self) -> bool:
        """Whether rounds re-cluster: ΔQ methods only (the median is the same every round)."""
        return self.networks.uses_synergy and self.networks.delta_q_preference

    def _preference(self, critic, replay: Replay, key, morph, synergy: Synergy) -> jax.Array:
        """algorithm.md §3: 1.2·softmax(ΔQ) ``[N]`` of morphology ``morph`` (traced) from
        ``delta_q_samples`` of its replay samples, with the online first critic under the
        morphology's current clustering ``synergy`` (unbatched)."""
        batch = sample(replay, key, morph, self.config.delta_q_samples)
        tree = jax.tree.map(lambda x: x[morph], self.tree)
        structure = Structure(self.agent_mask[morph], synergy, self.traversal[morph], tree)

        def q(obs, action):
            return self.td3.losses.q1(critic, obs, action, structure)

        return delta_q_preference(q, batch.obs, batch.action, structure.agent_mask)

    def _recluster_all(self, state: TrainerState, key: jax.Array) -> Synergy:
        """Every morphology re-clustered from the same critic (``update=fused``)."""
        if not self._reclusters():
            return state.synergy
        morphs = jnp.arange(self.num_morphs)
        keys = jax.vmap(lambda i: jax.random.fold_in(key, i))(morphs)
        preference = jax.vmap(self._preference, in_axes=(None, None, 0, 0, 0))(
            state.agent.critic, state.replay, keys, morphs, state.synergy
        )
        return self.affinity.cluster(preference)

    def _recluster_one(self, critic, replay: Replay, synergy: Synergy, morph, key) -> Synergy:
        """``synergy [M]`` with morphology ``morph`` re-clustered from ``critic``."""
        if not self._reclusters():
            return synergy
        own = jax.tree.map(lambda x: x[morph], synergy)
        preference = self._preference(critic, replay, key, morph, own)
        new = self.affinity.cluster_one(morph, preference)
        return jax.tree.map(lambda all_, one: all_.at[morph].set(one), synergy, new)

    def _diagnostics(self, agent: AgentState, replay: Replay, synergy: Synergy, key) -> dict:
        """Per morphology ``[M]``, the round's policy on ``batch_size`` replay states: the
        share of its actions with |a| > 0.99, the RMS of the action before the tanh (over
        the agents it acts for) and the RMS of SOLAR's gate (over real agents; 0 without)."""
        batch = sample_each(replay, key, jnp.arange(self.num_morphs), self.config.td3.batch_size)
        act = jax.vmap(self.networks.act_diagnostics, in_axes=(None, 0, 0, 0, 0, 0))
        inputs = (batch.obs, self.agent_mask, synergy, self.traversal, self.tree)
        action, inside = act(agent.actor, *inputs)
        acting = self.networks.acting_mask(self.agent_mask)[:, None, :]  # [M, 1, N]

        def mean(x, mask):  # over all but the morphology axis
            axes = tuple(range(1, x.ndim))
            mask = jnp.broadcast_to(mask, x.shape)
            return jnp.sum(jnp.where(mask, x, 0.0), axes) / jnp.maximum(jnp.sum(mask, axes), 1)

        gate = inside.get("gate_values")
        real = self.agent_mask[:, None, :, None]
        return {
            "saturated": mean((jnp.abs(action) > SATURATED).astype(jnp.float32), acting),
            "pre_tanh_rms": jnp.sqrt(mean(inside["pre_tanh"] ** 2, acting)),
            "gate_rms": jnp.zeros(self.num_morphs)
            if gate is None
            else jnp.sqrt(mean(gate**2, real)),
        }

    @functools.cached_property
    def slot_buckets(self) -> tuple[int, ...]:
        """The synergy slot counts the update is compiled for (``slot_buckets``; N_max
        alone without synergies)."""
        if not self.networks.uses_synergy:
            return (self.env.n_max,)
        return slot_buckets(self.env.n_max, self.config.synergy_buckets)

    def _in_slot_bucket(self, structure: Structure, loop, carry, lane_axis: LaneAxis):
        """``loop(structure, carry)`` with ``structure`` cut to the smallest slot bucket that
        holds its synergies (of every morphology it stacks): one branch per bucket.

        ``lane_axis``: the axis name(s) of a sweep's lanes (``training.lanes``). The lanes
        then take the bucket of the largest K among them: a per-lane index would make a
        vmapped switch run every branch. Rounding differs between buckets, so a lane may
        round differently from its single run (``tests/training/test_sweep.py`` compares within a
        tolerance)."""
        buckets = self.slot_buckets
        if len(buckets) == 1:
            return loop(structure, carry)
        index = slot_bucket(structure.synergy.num_synergies, buckets)
        if lane_axis is not None:
            index = jax.lax.pmax(index, lane_axis)

        def branch(slots: int):
            cut = structure.replace(synergy=structure.synergy.with_slots(slots))
            return lambda carry: loop(cut, carry)

        return jax.lax.switch(index, [branch(slots) for slots in buckets], carry)

    def train(
        self, state: TrainerState, steps: jax.Array, lane_axis: LaneAxis = None
    ) -> tuple[TrainerState, dict]:
        """``steps.sum() // (M_all × td3.update_every)`` TD3 iterations per training
        morphology (algorithm.md §5: ``update_every`` 1), re-clustering first, in the
        configured update mode (module docstring), each block of iterations in its synergy
        slot bucket (``_in_slot_bucket``; ``lane_axis``: the
        axis name(s) of a sweep's lanes, if any)."""
        key, cluster_key, update_key, diagnostics_key = jax.random.split(state.key, 4)
        iters = round_iterations(steps, self.num_morphs, self.config.td3.update_every)
        batch_size = self.config.td3.batch_size
        zero = jnp.float32(0.0)
        sums = dict(critic_loss=zero, actor_loss=zero, q=zero, actor_steps=jnp.int32(0))

        def accumulate(sums, metrics):
            return dict(
                critic_loss=sums["critic_loss"] + metrics["critic_loss"],
                actor_loss=sums["actor_loss"] + metrics["actor_loss"],
                q=sums["q"] + metrics["q"],
                actor_steps=sums["actor_steps"] + metrics["actor_step"].astype(jnp.int32),
            )

        if self.config.update == "sequential":

            def morph_block(j, carry):
                agent, synergy, sums = carry
                morph = self.update_order[j]
                synergy = self._recluster_one(
                    agent.critic,
                    state.replay,
                    synergy,
                    morph,
                    jax.random.fold_in(cluster_key, morph),
                )
                structure = jax.tree.map(lambda x: x[morph], self.structure(synergy))
                block_key = jax.random.fold_in(update_key, morph)
                # Held-out morphologies are re-clustered but give no gradients.
                block_iters = jnp.where(morph < self.num_train, iters, 0)

                def block(s: Structure, carry):
                    def iteration(i, carry):
                        agent, sums = carry
                        sample_key, noise_key = jax.random.split(jax.random.fold_in(block_key, i))
                        batch = sample(state.replay, sample_key, morph, batch_size)
                        agent, metrics = self.td3.update(agent, batch, s, i, noise_key, state.hyper)
                        return agent, accumulate(sums, metrics)

                    return jax.lax.fori_loop(0, block_iters, iteration, carry)

                agent, sums = self._in_slot_bucket(structure, block, (agent, sums), lane_axis)
                return agent, synergy, sums

            agent, synergy, sums = jax.lax.fori_loop(
                0, self.num_morphs, morph_block, (state.agent, state.synergy, sums)
            )
            total = iters * self.num_train
        else:
            synergy = self._recluster_all(state, cluster_key)
            train_ids = jnp.arange(self.num_train)
            train_structure = jax.tree.map(lambda x: x[: self.num_train], self.structure(synergy))

            def fused(s: Structure, carry):
                def iteration(i, carry):
                    agent, sums = carry
                    sample_key, noise_key = jax.random.split(jax.random.fold_in(update_key, i))
                    batch = sample_each(state.replay, sample_key, train_ids, batch_size)
                    agent, metrics = self.td3.fused_update(
                        agent, batch, s, i, noise_key, state.hyper
                    )
                    return agent, accumulate(sums, metrics)

                return jax.lax.fori_loop(0, iters, iteration, carry)

            agent, sums = self._in_slot_bucket(
                train_structure, fused, (state.agent, sums), lane_axis
            )
            total = iters

        state = state.replace(
            agent=agent,
            synergy=synergy,
            key=key,
            updates=state.updates + total,
            rounds=state.rounds + 1,
        )
        metrics = dict(
            iterations=total,
            critic_loss=sums["critic_loss"] / jnp.maximum(total, 1),
            actor_loss=sums["actor_loss"] / jnp.maximum(sums["actor_steps"], 1),
            q=sums["q"] / jnp.maximum(total, 1),
            actions=self._diagnostics(agent, state.replay, synergy, diagnostics_key),
        )
        metrics["finite"] = all_finite([agent, metrics["critic_loss"], metrics["actor_loss"]])
        return state, metrics


def round_iterations(steps: jax.Array, num_morphs: int, update_every: int) -> jax.Array:
    """int32 []: the TD3 iterations per training morphology after a round of ``steps
    [M_all]`` counted steps: one per ``update_every`` counted steps of each of the
    ``num_morphs`` (M_all) morphologies (the module docstring)."""
    return jnp.sum(steps) // (num_morphs * update_every)


def all_finite(tree) -> jax.Array:
    """bool []: every floating-point number of ``tree`` is finite (the round's health
    check, ``Runner``: a diverged run stops before its parameters are saved)."""
    leaves = [x for x in jax.tree.leaves(tree) if jnp.issubdtype(x.dtype, jnp.floating)]
    return jnp.all(jnp.stack([jnp.isfinite(x).all() for x in leaves]))


def plan(trainer: Trainer) -> str:
    """What a run would build: suite, sizes, parameter counts, replay memory."""
    config = trainer.config
    actor, critic = jax.eval_shape(trainer.networks.init, jax.random.PRNGKey(0))
    first = jax.eval_shape(trainer.init, config.seed).replay
    full = jax.eval_shape(lambda: trainer.init(config.seed, slots=trainer.capacity)).replay
    replay_bytes = tree_bytes(full)
    names = trainer.names
    if trainer.networks.uses_tree:
        widths = "-".join(str(s.shape[1]) for s in trainer.tree.senders) or "-"
        structure = (
            f"messages of {config.network.message_dim} between limbs, {trainer.max_children} "
            f"child slot(s), top-down senders per depth {widths}"
        )
    elif trainer.networks.uses_synergy:
        structure = f"the update compiled for {', '.join(map(str, trainer.slot_buckets))} "
        structure += "synergy slots"
    else:
        structure = "no synergies"
    return "\n".join(
        [
            f"suite {config.morph}: train {', '.join(names[: trainer.num_train])}",
            f"  held out: {', '.join(names[trainer.num_train :]) or '-'}",
            f"method {config.method}, {config.schedule} schedule: update {config.update}, "
            f"net {config.net}, N_max {trainer.env.n_max}, {config.num_envs} env(s) per "
            f"morphology, {_rounds(config)}, batch {config.td3.batch_size}, one TD3 iteration per "
            f"{config.td3.update_every} counted step(s) per morphology; {structure}",
            f"physics: {trainer.env.layout_summary()}",
            f"collection: {len(trainer.parts)} program(s) for {len(trainer.env.worlds)} MJX "
            f"world(s) (collect={config.collect}); exploration noise std {_noise(config.td3)}",
            _variation(trainer),
            f"parameters: actor {_size(actor):,}, twin critics {_size(critic):,}",
            f"replay: {trainer.capacity:,} transitions per morphology, "
            f"{replay_bytes / 2**30:.2f} GiB on the device when full (allocated as it "
            f"fills, from {first.capacity:,}); a round's staging buffer "
            f"{tree_bytes(trainer.staging()) / 2**20:,.1f} MiB",
            f"total {config.total_steps:,} counted env steps (all morphologies); warm-up "
            f"{config.td3.warmup_steps * trainer.num_morphs:,}",
        ]
    )


def tree_bytes(tree) -> int:
    """The bytes of the arrays (or shapes) of ``tree``."""
    return sum(x.size * x.dtype.itemsize for x in jax.tree.leaves(tree))


def _variation(trainer: Trainer) -> str:
    env = trainer.config.env
    if not trainer.env.redraw:
        return "robots: nominal (env.variation off)"
    return (
        f"robots: domain randomisation over {env.variation} (a pool of "
        f"{trainer.env.num_variants} per robot, the nominal first, seed {env.variation_seed}; "
        "evaluations on the nominal robots)"
    )


def _rounds(config: TrainConfig) -> str:
    if config.round_steps:
        return f"rounds of {config.round_steps} steps per env (episodes go on across them)"
    return "rounds of one episode per env"


def _noise(td3) -> str:
    low, high = td3.exploration_noise_min, td3.exploration_noise
    return f"{high:g}" if low is None else f"per environment and round from [{low:g}, {high:g}]"


def _size(tree) -> int:
    return sum(x.size for x in jax.tree.leaves(tree))
