"""All morphologies of a suite (held-out ones included) in one jitted step.

This is where heterogeneity stops: everything leaving ``MultiEnv`` is padded, with
morphologies ``M`` in suite order, ``B`` environments per morphology and agents padded
to ``N_max``:

    observations   [M, B, N_max, 19]      actions   [M, B, N_max] (torso, padding ignored)
    reward, terminated, truncated, valid   [M, B]
    agent_mask     [M, N_max] (static)

Internally the suite is split into worlds (``env.layout``): a union of robots, each an
environment of one model's variants (``solar_jax.env.union``: ``vmap`` over its robots),
or a robot alone (``solar_jax.env.world``). Each world's pure step is vmapped over ``B``
(called on the one environment when ``B = 1``, the paper's setting: MJX traces 1.7x as
long under ``vmap``) and all worlds are stepped in the same traced function. Robot
``i``'s resets draw from the key its world would have alone (``fold_in`` of its index
among worlds of one robot each), whatever the layout. ``part(worlds)`` is the env of
some worlds alone (their robots, ``morph_ids`` into the suite), with the same keys, so
that each can be its own program: a part's reset and steps equal the whole env's on its
robots.
"""

import copy
import functools
from collections.abc import Sequence
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from flax import struct

from solar_jax.config import EnvConfig
from solar_jax.env.physics import WorldState, make_world_fns
from solar_jax.env.union import build_union_world, make_union_fns
from solar_jax.env.variants import make_pool
from solar_jax.env.world import OBS_SIZE, build_world, plan_worlds
from solar_jax.morphology import Morphology, get_suite, load
from solar_jax.morphology.union import plan_unions
from solar_jax.morphology.variants import Variation, make_variants


@struct.dataclass
class MultiState:
    worlds: tuple[WorldState, ...]  # each batched over B
    obs: jnp.ndarray  # [M, B, N, 19] observation of the current states
    nonfinite_resets: jnp.ndarray  # [M] int32, states reset because they blew up


@struct.dataclass
class Transition:
    """One step of every environment, ready for replay (``valid`` marks what to store)."""

    obs: jnp.ndarray  # [M, B, N, 19]
    action: jnp.ndarray  # [M, B, N]
    reward: jnp.ndarray  # [M, B]
    next_obs: jnp.ndarray  # [M, B, N, 19] the true next observation, also at episode ends
    terminated: jnp.ndarray  # [M, B] bool (not truncated: bootstrap through time limits)
    truncated: jnp.ndarray  # [M, B] bool
    valid: jnp.ndarray  # [M, B] bool: False where the physics blew up
    episode_return: jnp.ndarray  # [M, B] finished episodes' returns where done, else 0
    episode_length: jnp.ndarray  # [M, B] finished episodes' lengths where done, else 0

    @property
    def done(self) -> jnp.ndarray:
        return self.terminated | self.truncated | ~self.valid


class RobotPlace(NamedTuple):
    """A robot's place in a ``MultiState``: world ``world``, robot ``robot`` of it (the
    index of its ``[B, R]`` fields); its data ``state.worlds[world].data.X[b][data]``, its
    own qpos and dofs, in its order, at ``qpos`` and ``dofs`` of that."""

    world: int
    robot: int
    data: tuple
    qpos: np.ndarray
    dofs: np.ndarray


class MultiEnv:
    """The padded batch of a suite: ``reset(key)`` and ``step(state, actions)``, both pure."""

    def __init__(
        self,
        morphs: str | Sequence[Morphology | str],
        batch_size: int,
        config: EnvConfig | None = None,
        variants: Sequence[Sequence[Morphology]] | None = None,
        redraw: bool = False,
    ):
        """``variants``: per robot of the suite, ``P`` variants of it
        (``morphology.variants``; the same ``P`` for all). Environment ``b`` then runs
        variant ``b % P`` of every robot, or with ``redraw`` a variant drawn from the ``P``
        at each episode (domain randomisation). Without ``variants``, ``config.variation``
        builds them (``variation_pool`` per robot, the nominal robot first) and redraws."""
        config = config or EnvConfig()
        if isinstance(morphs, str):  # a suite (or one robot) by name
            morphs = get_suite(morphs).members
        morphs = [load(m) if isinstance(m, str) else m for m in morphs]
        if batch_size < 1:
            raise ValueError(f"batch_size must be >= 1, got {batch_size}")
        self.morphs = tuple(morphs)
        self.names = tuple(m.name for m in self.morphs)
        self.batch_size = batch_size
        self.config = config
        self.n_max = max(m.num_agents for m in self.morphs)
        if variants is None and config.variation:
            variants, redraw = _variation_pools(self.morphs, config), True
        self.num_variants = _check_variants(self.morphs, variants)
        self.redraw = redraw and self.num_variants > 0
        alone = plan_worlds(self.morphs, 1)  # a model per robot, grouped by physics
        # Robot i's resets draw from key id ``key_id[i]``: its world's in a model per robot.
        key_id = np.argsort(np.concatenate(alone))
        unions = config.layout in ("union", "family")
        if unions:
            self.groups = plan_unions(self.morphs, grow=config.layout == "union")
        else:
            self.groups = alone
        self.worlds, self.pools, self._fns, self._keys, self.unions = [], [], [], [], []
        for group in self.groups:
            robots = tuple(self.morphs[i] for i in group)
            own_variants = None if variants is None else [variants[i] for i in group]
            if unions and len(group) > 1:
                union = build_union_world(robots, self.n_max, config, own_variants)
                world, pool, fns = union.world, union.pool, make_union_fns(union, config, redraw)
            else:
                union, world = None, build_world(robots, self.n_max)
                pool = None
                if own_variants is not None:
                    pool = make_pool(
                        world,
                        [
                            build_world(tuple(v[p] for v in own_variants), self.n_max)
                            for p in range(self.num_variants)
                        ],
                        config.fix_humanoid_limb_types,
                    )
                fns = make_world_fns(world, config, pool=pool, redraw=redraw)
            self.worlds.append(world)
            self.pools.append(pool)  # each world's VariantPool (a union's robots), or None
            self._fns.append(fns)
            self._keys.append(key_id[group])  # each robot's key id
            self.unions.append(union)  # each world's UnionWorld, or None
        # Worlds' robots, concatenated, are a permutation of the suite order.
        self._order = np.argsort(np.concatenate(self.groups))
        self.world_ids = tuple(range(len(self.worlds)))  # each world's index in the suite's
        self.morph_ids = tuple(range(len(self.morphs)))  # each robot's index in the suite
        mask = np.zeros((len(self.morphs), self.n_max), bool)
        for i, m in enumerate(self.morphs):
            mask[i, : m.num_agents] = True
        self.agent_mask = mask
        self.dt = np.array([m.dt for m in self.morphs])

    @property
    def num_morphs(self) -> int:
        return len(self.morphs)

    def locate(self, i: int) -> RobotPlace:
        """Where robot ``i`` of the suite lives in a ``MultiState``."""
        world = next(w for w, group in enumerate(self.groups) if i in group)
        r = self.groups[world].index(i)
        union = self.unions[world]
        if union is not None:
            emb = union.union.embeddings[r]
            return RobotPlace(world, r, (r,), emb.qpos, emb.dof)
        layout = self.worlds[world]
        qpos, dofs = np.flatnonzero(layout.qpos_robot == r), np.flatnonzero(layout.dof_robot == r)
        return RobotPlace(world, r, (), qpos, dofs)

    def layout_summary(self) -> str:
        """The physics' layout in words: each union's host and robots, robots alone and why."""
        if self.config.layout == "per_robot":
            return f"{len(self.worlds)} MJX model(s), one per robot (env.layout=per_robot)"
        parts, alone = [], []
        for group, union in zip(self.groups, self.unions, strict=True):
            if union is None:
                alone.append(self.names[group[0]])
                continue
            extra = union.union.body_ratio
            parts.append(
                f"{self.names[group[0]]}'s tree holds {len(group)} robots (each steps "
                f"{extra.min():.2g}-{extra.max():.2g}x its own bodies)"
            )
        if alone:
            why = (
                "no other robot shares its physics settings, or its collision bits are not 0/1"
                if self.config.layout == "union"
                else "it embeds in no other robot's tree"
            )
            parts.append(f"{', '.join(alone)} alone ({why})")
        return f"{len(self.worlds)} MJX model(s): " + "; ".join(parts)

    def models(self) -> list:
        """Every MuJoCo model the env's programs are traced from: each world's, and each
        robot's own (a union's robots are data of its world's program)."""
        return [w.model for w in self.worlds] + [m.model for m in self.morphs]

    def part(self, worlds: Sequence[int]) -> "MultiEnv":
        """The env of ``worlds`` (indices into ``self.worlds``) alone: their robots in the
        worlds' order (``morph_ids``: their indices in the suite), padded to the suite's
        ``n_max``, reset and stepped with the keys the whole env gives them."""
        part = copy.copy(self)
        robots = [i for w in worlds for i in self.groups[w]]
        part.morphs = tuple(self.morphs[i] for i in robots)
        part.names = tuple(m.name for m in part.morphs)
        part.morph_ids = tuple(self.morph_ids[i] for i in robots)
        part.world_ids = tuple(self.world_ids[w] for w in worlds)
        part.worlds = [self.worlds[w] for w in worlds]
        part._fns = [self._fns[w] for w in worlds]
        part.pools = [self.pools[w] for w in worlds]
        part._keys = [self._keys[w] for w in worlds]
        part.unions = [self.unions[w] for w in worlds]
        sizes = np.cumsum([0] + [len(self.groups[w]) for w in worlds])
        part.groups = [list(range(a, b)) for a, b in zip(sizes[:-1], sizes[1:], strict=True)]
        part._order = np.arange(len(robots))
        part.agent_mask = self.agent_mask[robots]
        part.dt = self.dt[robots]
        return part

    def with_batch_size(self, batch_size: int) -> "MultiEnv":
        """The same worlds with ``batch_size`` environments per robot (an evaluation's)."""
        if batch_size < 1:
            raise ValueError(f"batch_size must be >= 1, got {batch_size}")
        env = copy.copy(self)
        env.batch_size = batch_size
        return env

    @property
    def obs_shape(self) -> tuple[int, int, int, int]:
        return (self.num_morphs, self.batch_size, self.n_max, OBS_SIZE)

    def _over_batch(self, fn):
        """``fn`` over the leading ``B`` axis of its arguments and results: ``jax.vmap``, or
        for one environment ``fn`` of it: the same computation up to float rounding, and
        MJX traces it about 40% faster without vmap's batching rules (docs/design.md)."""
        if self.batch_size > 1:
            return jax.vmap(fn)

        def one(*args):
            out = fn(*jax.tree.map(lambda x: x[0], args))
            return jax.tree.map(lambda x: x[None], out)

        return one

    def _gather(self, per_world: list[jnp.ndarray]) -> jnp.ndarray:
        """Per-world ``[B, R, ...]`` -> suite order ``[M, B, ...]``."""
        stacked = jnp.concatenate([jnp.swapaxes(x, 0, 1) for x in per_world], axis=0)
        return stacked[self._order]

    def reset(self, key: jnp.ndarray, nominal=False) -> MultiState:
        """``nominal`` (bool, may be traced): environments that redraw variants start as
        the nominal robots (their pools' first variant), for evaluations."""
        if not self.redraw:
            return self._start(key, [fns.reset for fns in self._fns])
        starts = [functools.partial(fns.reset, nominal=nominal) for fns in self._fns]
        return self._start(key, starts)

    def blank(self, key: jnp.ndarray) -> MultiState:
        """A state with ``reset``'s shapes and types (zeros), traced without MJX: for the
        shapes of programs that take a state."""
        return self._start(key, [fns.blank for fns in self._fns])

    def going_on(self, worlds: Sequence[WorldState]) -> MultiState:
        """The state of environments stepped before, from their worlds' states (in the
        order of ``self.worlds``): how rounds of bounded length go on from the last."""
        return MultiState(
            worlds=tuple(worlds),
            obs=self._gather([s.obs for s in worlds]),
            nonfinite_resets=jnp.zeros(self.num_morphs, jnp.int32),
        )

    def _start(self, key: jnp.ndarray, starts: list) -> MultiState:
        def start(fn, key_ids: np.ndarray, robots: int, union: bool):
            keys = [jax.random.split(jax.random.fold_in(key, i), self.batch_size) for i in key_ids]
            per_robot = max(self.num_variants, 1)
            ids = np.arange(self.batch_size, dtype=np.int32) % per_robot
            variant = np.repeat(ids[:, None], robots, 1)  # [B, R]: environment b's
            if union:  # a robot per key; robot g's entries start at g * P
                variant += np.arange(robots, dtype=np.int32) * per_robot
                return self._over_batch(fn)(jnp.stack(keys, axis=1), jnp.asarray(variant))
            if not self.num_variants:
                return self._over_batch(fn)(keys[0])
            return self._over_batch(fn)(keys[0], jnp.asarray(variant))

        worlds = tuple(
            start(fn, key_ids, len(group), union is not None)
            for fn, key_ids, group, union in zip(
                starts, self._keys, self.groups, self.unions, strict=True
            )
        )
        return MultiState(
            worlds=worlds,
            obs=self._gather([s.obs for s in worlds]),
            nonfinite_resets=jnp.zeros(self.num_morphs, jnp.int32),
        )

    def step(self, state: MultiState, actions: jnp.ndarray) -> tuple[MultiState, Transition]:
        """``actions [M, B, N_max]``; returns the new state and this step's transitions."""
        new_worlds, outs = [], []
        for group, fns, world_state in zip(self.groups, self._fns, state.worlds, strict=True):
            world_actions = jnp.swapaxes(actions[np.asarray(group)], 0, 1)  # [B, R, N]
            new_state, out = self._over_batch(fns.step)(world_state, world_actions)
            new_worlds.append(new_state)
            outs.append(out)

        def field(name: str) -> jnp.ndarray:
            return self._gather([getattr(o, name) for o in outs])

        nonfinite = field("nonfinite")
        transition = Transition(
            obs=state.obs,
            action=actions,
            reward=field("reward"),
            next_obs=field("next_obs"),
            terminated=field("terminated"),
            truncated=field("truncated"),
            valid=~nonfinite,
            episode_return=field("episode_return"),
            episode_length=field("episode_length"),
        )
        new_state = MultiState(
            worlds=tuple(new_worlds),
            obs=self._gather([s.obs for s in new_worlds]),
            nonfinite_resets=state.nonfinite_resets + nonfinite.sum(axis=1, dtype=jnp.int32),
        )
        return new_state, transition


def _check_variants(morphs, variants) -> int:
    """The number of variants per robot (0: none), the same for every robot."""
    if variants is None:
        return 0
    if len(variants) != len(morphs):
        raise ValueError(f"variants for {len(variants)} robots, the suite has {len(morphs)}")
    counts = {len(v) for v in variants}
    if len(counts) != 1 or 0 in counts:
        raise ValueError(f"every robot needs the same number (>= 1) of variants, got {counts}")
    for morph, own in zip(morphs, variants, strict=True):
        if any(v.agents != morph.agents for v in own):
            raise ValueError(f"a variant of {morph.name} has other agents than it")
    return counts.pop()


def _variation_pools(morphs, config: EnvConfig) -> list[list[Morphology]]:
    """Each robot's pool for ``config.variation``: itself, then ``variation_pool - 1``
    variants in which every named property varies."""
    variation, properties = Variation.parse(config.variation)
    count, seed = config.variation_pool - 1, config.variation_seed
    return [
        [m]
        + ([v.morph for v in make_variants(m, properties, count, seed, variation)] if count else [])
        for m in morphs
    ]
