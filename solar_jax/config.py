"""Typed, frozen configuration: the leaf every other module imports (it imports nothing
of the project). Counts and shapes are static; derived values are properties, or live in
a run's saved "resolved" section. Each field's docstring says what it does and where its
default comes from.
"""

import dataclasses
import math
import types
import typing


class ConfigError(ValueError):
    """A bad setting (command line, experiment file, saved run); the message names the key
    and what is valid."""


INT_LIMIT = 2**31 - 1
"""The largest integer a config holds: counters, seeds and sizes reach the programs as
int32 (``jax.random.PRNGKey`` of a traced seed, ``TrainerState``'s step counters)."""


def check_numbers(config, prefix: str = "") -> None:
    """Every number of a config dataclass (not its nested ones) finite, and every integer
    within ``INT_LIMIT``: one check for all fields, before the fields' own ranges."""
    for field in dataclasses.fields(config):
        value = getattr(config, field.name)
        for item in value if isinstance(value, tuple) else (value,):
            if isinstance(item, bool) or not isinstance(item, int | float):
                continue
            if isinstance(item, float) and not math.isfinite(item):
                raise ValueError(f"{prefix}{field.name} must be a finite number, got {item}")
            if isinstance(item, int) and abs(item) > INT_LIMIT:
                raise ValueError(
                    f"{prefix}{field.name}={item}: integers must be within ±{INT_LIMIT:,} (int32)"
                )


Method = typing.Literal[
    "solar", "solar_no_pref", "amorpheus", "amorpheus_mask", "smp", "monolithic"
]
METHODS: tuple[str, ...] = typing.get_args(Method)
"""The methods a config may name; ``networks.registry`` builds each (a test checks both
lists agree)."""


def _traced(default: float | None):
    """A ``TD3Config`` field the jitted programs read as a traced scalar (``TD3_TRACED``)."""
    return dataclasses.field(default=default, metadata={"traced": True})


@dataclasses.dataclass(frozen=True)
class EnvConfig:
    """Physics and task settings of the MJX environment (algorithm.md §1 and §2)."""

    solver_iterations: int = 4
    """Constraint solver (Newton) iterations. MuJoCo's default is 100, which makes MJX
    6-10x slower under vmap; 4 is converged for these robots (benchmarks/README.md)."""

    ls_iterations: int = 8
    """Line-search iterations of the solver (MuJoCo's default: 50)."""

    layout: typing.Literal["union", "family", "per_robot"] = "union"
    """How a suite's robots become MJX programs. union: every robot is a variant of one
    model, the largest robot's body tree grown until each embeds in it (one per physics
    setting: cheetahs, Euler at 0.01 s, apart), one program, each robot's own physics
    (``env.union``); family: a union per family, of the robots that embed in its largest
    without growth; per_robot: a model per robot.
    benchmarks/README.md, compile and start."""

    fix_humanoid_limb_types: bool = False
    """The reference feeds all-zero limb-type one-hots for 2-D humanoids (algorithm.md §2);
    True gives them their hip/knee/shoulder/elbow types instead."""

    max_episode_steps: int = 1000
    """Time limit, ended as a truncation (bootstrapped through)."""

    variation: str = ""
    """Domain randomisation ('': off): the properties to vary, as ``python -m
    solar_jax.evaluate``'s ``variants=`` (``dynamics``, ``all``, ``gear=0.9:1.1``, ...).
    Each robot's episodes then run on a variant drawn from its pool; evaluations run
    the nominal robots."""

    variation_pool: int = 64
    """Variants per robot drawn when the env is built (the first is the nominal robot);
    with ``variation``, every episode runs one of them, drawn uniformly."""

    variation_seed: int = 0
    """Seed of the pool's variants."""

    def __post_init__(self):
        check_numbers(self, "env.")
        if self.variation_pool < 1:
            raise ValueError(f"env.variation_pool must be >= 1, got {self.variation_pool}")
        for name in ("solver_iterations", "ls_iterations"):
            if getattr(self, name) < 1:
                raise ValueError(f"env.{name} must be >= 1, got {getattr(self, name)}")
        if self.max_episode_steps < 2:  # an episode of L steps counts L - 1
            raise ValueError(
                f"env.max_episode_steps must be >= 2 (an episode of L steps counts L - 1), "
                f"got {self.max_episode_steps}"
            )


@dataclasses.dataclass(frozen=True)
class TD3Config:
    """TD3 as the paper ran it (algorithm.md §5). The fields declared ``_traced`` reach the
    jitted update as traced scalars (``TD3_TRACED``: the learning rates through the
    optimiser states, the rest as ``agent.Hyper``), so a sweep's lanes may differ in them;
    every other field is static: a change recompiles."""

    lr: float = _traced(1e-4)
    """Adam learning rate of the actor and critic optimisers."""

    synergy_lr: float | None = _traced(None)
    """Adam learning rate of the synergy (action transformation) optimiser; None: ``lr``."""

    grad_clip: float = 0.1
    """Gradient global-norm clip, applied per optimiser (static); 0: none (SMP's reference
    runs, ``METHOD_KEYS``)."""

    batch_size: int = 100
    """Transitions per morphology per update."""

    discount: float = _traced(0.99)
    """γ of the TD target (bootstrapped through time-limit truncations, not terminations)."""

    tau: float = _traced(0.046)
    """Polyak rate of both target networks, applied on actor iterations."""

    policy_noise: float = _traced(0.2)
    """Std of the target policy smoothing noise, as a fraction of the action range [-1, 1]."""

    noise_clip: float = _traced(0.5)
    """The target policy smoothing noise is clipped to ±``noise_clip``."""

    policy_delay: int = 2
    """The actor and the targets step on every ``policy_delay``-th iteration."""

    synergy_delay: int = 4
    """The synergy optimiser steps on every ``synergy_delay``-th iteration."""

    exploration_noise: float = _traced(0.126)
    """Std of the Gaussian noise added to the policy's actions while collecting."""

    exploration_noise_min: float | None = None
    """None: every environment explores with std ``exploration_noise``. A number: each
    environment's std is drawn per round (in rounds of bounded length, per episode)
    uniformly from [``exploration_noise_min``, ``exploration_noise``] (FastTD3's
    per-environment noise scales), so some episodes stay near the deterministic policy
    while others explore widely. Static."""

    update_every: int = 1
    """Counted env steps per TD3 iteration of each training morphology: a round runs
    ``counted steps // (M_all × update_every)`` iterations per training morphology. 1: the
    paper's (algorithm.md §5). Many environments per morphology (``num_envs``) with large
    batches update less often per step."""

    warmup_steps: int = 2000
    """Uniform random actions for the first ``warmup_steps`` × (all morphologies, held-out
    ones included, as the reference counts) counted env steps. Updates run during it too."""

    gate_group: typing.Literal["actor", "synergy"] = "actor"
    """Which optimiser steps the action transformation's gate MLP. actor (the reference,
    algorithm.md §4): the actor's Adam and clip on actor iterations, Polyak-averaged into
    the target actor, whose gate the TD target uses. synergy (this project before): the
    synergy module's Adam every ``synergy_delay`` iterations, no target copy."""

    action_penalty: float = 0.0
    """λ of a penalty λ · mean(u²) on the actor's action u before its tanh (over the agents
    it acts for), added to the actor loss. 0: the reference (no penalty). Beyond the
    reference: it pulls saturated actions back where the critic's gradient reaches them
    (the fast schedule's 0.1; benchmarks/README.md, schedules). Static: a change
    recompiles."""

    def __post_init__(self):
        check_numbers(self, "td3.")
        for name in ("batch_size", "policy_delay", "synergy_delay", "update_every"):
            if getattr(self, name) < 1:
                raise ValueError(f"td3.{name} must be >= 1, got {getattr(self, name)}")
        if not self.lr > 0:
            raise ValueError(f"td3.lr must be > 0, got {self.lr}")
        if self.grad_clip < 0:
            raise ValueError(f"td3.grad_clip must be >= 0 (0: none), got {self.grad_clip}")
        if self.synergy_lr is not None and not self.synergy_lr > 0:
            raise ValueError(f"td3.synergy_lr must be > 0, got {self.synergy_lr}")
        if not 0 <= self.discount <= 1 or not 0 < self.tau <= 1:
            raise ValueError(f"td3.discount must be in [0, 1] and td3.tau in (0, 1]: {self}")
        nonnegative = ("policy_noise", "noise_clip", "exploration_noise", "warmup_steps")
        for name in (*nonnegative, "action_penalty"):
            if getattr(self, name) < 0:
                raise ValueError(f"td3.{name} must be >= 0, got {getattr(self, name)}")

        low = self.exploration_noise_min
        if low is not None and not 0 <= low <= self.exploration_noise:
            raise ValueError(
                f"td3.exploration_noise_min must be in [0, td3.exploration_noise = "
                f"{self.exploration_noise}], got {low}"
            )

    @property
    def transform_lr(self) -> float:
        """The synergy optimiser's learning rate (``synergy_lr``, else ``lr``)."""
        return self.lr if self.synergy_lr is None else self.synergy_lr


TD3_TRACED: tuple[str, ...] = tuple(
    f.name for f in dataclasses.fields(TD3Config) if f.metadata.get("traced")
)
"""The traced ``TD3Config`` fields: what a sweep may grid over (``solar_jax.sweep``)."""


@dataclasses.dataclass(frozen=True)
class NetworkConfig:
    """Sizes of the SOLAR, Amorpheus, SMP and monolithic networks; defaults are algorithm.md
    §4's."""

    width: int = 128
    """Transformer d_model; the per-agent encoder scales its output by sqrt(width)."""

    heads: int = 2
    """Attention heads per transformer layer; must divide ``width``."""

    feedforward: int = 256
    """Hidden size of each layer's ReLU feed-forward block."""

    num_layers: int = 3
    """Transformer layers. SOLAR: layer 0 is intra-synergy, the rest inter-synergy (1 + 2).
    Amorpheus uses the same count over agents."""

    transform_dim: int = 64
    """d of the action transformation: each of the 4 heads gets a scalar k1 and a (d-1)-vector
    e per agent. d = 1 (the reference README's value) zeroes every non-exemplar action."""

    transform_heads: int = 4
    """Heads s of the action transformation, averaged (algorithm.md §4: 4)."""

    embedding_dim: int = 64
    """Width of each of the three traversal embedding tables (pre, in, post order)."""

    gate_hidden: int = 256
    """Hidden size of the transform's gate MLP (width + 4d -> gate_hidden -> ReLU -> 4)."""

    hard_mask: bool = False
    """False (the code's, default): layer 0 adds the soft bias log(Ŵ Ŵᵀ). True (the paper's
    text): layer 0 blocks attention across synergies instead."""

    paper_transform: bool = False
    """False (the code's, default): exemplar rows masked by membership, times a state gate.
    True (the paper's text): T's columns averaged over each cluster's members, no gate."""

    mlp_hidden: tuple[int, ...] = (400, 300)
    """Hidden sizes of TD3's MLPs (400-300): the monolithic baseline's actor and critic,
    and SMP's action, Q and top-down message heads (``MLPBase``)."""

    message_dim: int = 32
    """SMP: the size of a message between limbs (``msg_dim``)."""

    message_width: int = 64
    """SMP: the hidden width of the bottom-up module (its fc1 and fc2)."""

    init: typing.Literal["reference", "flax"] = "reference"
    """reference (default): the authors' PyTorch initialisation (algorithm.md §4: encoder
    and decoder U(±0.1), PyTorch Linear defaults, xavier in-projection, embeddings
    N(0, 1), the layers of one network identical at init). flax: Flax's initialisers."""

    torso_action: bool = True
    """True (the reference): the actor outputs an action for the torso too, which the
    replay stores, the critic reads and target noise perturbs (the physics ignores it).
    False: the torso's action is zeroed everywhere."""

    def __post_init__(self):
        check_numbers(self, "network.")
        for name in (
            "width",
            "heads",
            "feedforward",
            "num_layers",
            "transform_dim",
            "transform_heads",
            "embedding_dim",
            "gate_hidden",
            "message_dim",
            "message_width",
        ):
            if getattr(self, name) < 1:
                raise ValueError(f"network.{name} must be >= 1, got {getattr(self, name)}")
        if self.width % self.heads:
            raise ValueError(f"network.heads ({self.heads}) must divide width ({self.width})")
        if self.init not in typing.get_args(NetworkConfig.__annotations__["init"]):
            raise ValueError(f"network.init must be reference or flax, got {self.init!r}")
        if not self.mlp_hidden or min(self.mlp_hidden) < 1:
            raise ValueError(f"network.mlp_hidden must be positive sizes, got {self.mlp_hidden}")

    @classmethod
    def tiny(cls, **overrides) -> "NetworkConfig":
        """Small sizes for CPU smoke runs and tests (1 intra-synergy + 1 inter-synergy layer)."""
        sizes = dict(
            width=16,
            num_layers=2,
            heads=2,
            feedforward=32,
            transform_dim=4,
            embedding_dim=8,
            gate_hidden=16,
            mlp_hidden=(32, 32),
            message_dim=8,
            message_width=16,
        )
        return cls(**(sizes | overrides))

    @classmethod
    def small(cls, **overrides) -> "NetworkConfig":
        """Between tiny and the paper's sizes, for CPU learning curves: the paper's three
        layers (1 intra + 2 inter) at a quarter of its widths, d = 8. Sized to cost at most
        ~3x tiny per TD3 iteration on 2 CPU cores (benchmarks/README.md, learner.py)."""
        sizes = dict(
            width=32,
            num_layers=3,
            heads=2,
            feedforward=64,
            transform_dim=8,
            embedding_dim=16,
            gate_hidden=64,
            mlp_hidden=(64, 64),
            message_dim=16,
            message_width=32,
        )
        return cls(**(sizes | overrides))

    @classmethod
    def preset(cls, name: str) -> "NetworkConfig":
        """``net=``'s presets: default (algorithm.md §4), small, tiny."""
        presets = {"default": cls, "small": cls.small, "tiny": cls.tiny}
        if name not in presets:
            raise ValueError(f"net={name}: expected one of {', '.join(presets)}")
        return presets[name]()


SCHEDULES: dict[str, dict[str, str]] = {
    "paper": {},
    "fast": {
        "num_envs": "16",
        "update": "fused",
        "td3.batch_size": "256",
        "td3.update_every": "4",
        "td3.lr": "1e-3",
        "td3.action_penalty": "0.1",
        "td3.exploration_noise": "0.4",
        "td3.exploration_noise_min": "0",
        "network.torso_action": "false",
    },
}
"""What ``schedule=`` sets, as ``key=value`` text (the command line's keys go on top). The
fast schedule's measurements, ingredient by ingredient: benchmarks/README.md, schedules."""

METHOD_KEYS: dict[str, dict[str, str]] = {
    "smp": {"td3.grad_clip": "0"},
}
"""What ``method=`` sets where the reference ran the method otherwise than section 5 (as
``key=value`` text, after the schedule's keys; the command line's go on top): SMP's
scripts clip no gradient (algorithm.md §4.x)."""

MAX_TOTAL_STEPS = 10**9
"""``total_steps``' ceiling: the int32 step counters (``INT_LIMIT``) with room for the
round that crosses it (100 times the paper's 10M)."""


@dataclasses.dataclass(frozen=True)
class TrainConfig:
    """One training run: ``python -m solar_jax.train key=value ...`` (docs/training.md)."""

    morph: str = "humanoid++"
    """A suite (walker++, humanoid++, hopper++, whh++, cheetah++), a robot name or an MJCF
    path. Held-out robots are rolled out and clustered but give no gradients."""

    method: Method = "solar"
    """solar, solar_no_pref, amorpheus, amorpheus_mask, smp or monolithic."""

    seed: int = 0
    """Seeds the parameters, the exploration, the replay sampling and the evaluation."""

    total_steps: int = 10_000_000
    """Counted env steps, summed over all morphologies, held-out ones included (the
    reference's counter, algorithm.md §5; an episode of L steps counts L - 1)."""

    schedule: typing.Literal["paper", "fast"] = "paper"
    """paper: one environment per morphology, batch 100, one TD3 iteration per counted step
    (algorithm.md §5). fast (beyond the paper): many environments per morphology, large
    fused batches, one iteration per ``td3.update_every`` counted steps; the keys it sets
    (``SCHEDULES``) apply unless given on the command line."""

    update: typing.Literal["sequential", "fused"] = "sequential"
    """sequential (the reference): each iteration one morphology's batch, morphologies in
    turn. fused: each iteration one step on every training morphology's batch at once."""

    net: typing.Literal["default", "small", "tiny"] = "default"
    """Network preset: default (algorithm.md §4), small (CPU learning curves) or tiny (CPU
    smoke runs and tests). It replaces a ``network`` left at the defaults (here, once:
    ``__post_init__``); the command line applies ``network.*`` on top of the preset."""

    out: str = ""
    """Run directory; empty: runs/<morph>-<method>-seed<seed>-<time>."""

    resume: str = ""
    """A run directory to continue from its last checkpoint (its config is reused; only
    total_steps and the logging/eval/checkpoint settings may change)."""

    num_envs: int = 1
    """Environments per morphology (the reference: 1)."""

    round_steps: int = 0
    """0 (the paper's, algorithm.md §5): a round lasts until every environment has ended
    one episode. N > 0: a round steps every environment of every morphology N times, its
    episodes going on across rounds and resetting on their own (continuous collection,
    as FastTD3's), every transition stored; the environments between rounds are part of
    the state (and of a checkpoint), and the warm-up ends with the first round that
    starts past it."""

    synergy_buckets: int = 3
    """SOLAR: how many synergy-slot counts the update is compiled for (``slot_buckets``:
    3 -> (5, 7, 9) at N_max = 9, (4, 6, 7) at 7; N_max <= 3: one). Each round's iterations
    of a morphology (``fused``: of all) run the smallest that holds its K synergies, as the
    reference runs its inter-synergy layers on K tokens: the same numbers up to float
    rounding, fewer ms per iteration (benchmarks/README.md, learner), one more compiled
    update per bucket. 1: always N_max slots (padded and masked)."""

    collect: typing.Literal["auto", "per_world", "joint"] = "auto"
    """How the round's collection is compiled: per_world, a program per MJX world, compiled
    side by side (with enough cores a cold start is the largest robot's, not the
    suite's); joint, every world in one program (less compilation in all: faster on 2
    cores); auto: per_world on an accelerator or a CPU of 4 cores or more, else joint.
    The same episodes either way, up to float rounding (benchmarks/README.md)."""

    replay_capacity: int = 0
    """Transitions per morphology's ring; 0: the reference's 1e6, or 1e7 / M_all with more
    than 10 morphologies (held-out ones included), allocated as it fills without changing
    any result (``trainer.replay_slots``). A given capacity is allocated whole."""

    replay_continued: bool = True
    """Environments that finished their round's episode keep stepping after the auto-reset
    until the round ends. True (the reference, algorithm.md §5): those transitions are
    stored (never counted as steps). False: only each environment's first episode.
    Episode rounds only (``round_steps`` 0)."""

    delta_q_samples: int = 1000
    """Replay samples per morphology for the ΔQ preference (algorithm.md §3)."""

    eval_every: int = 50_000
    """Counted env steps between deterministic evaluations (0: only at the end)."""

    eval_episodes: int = 1
    """Deterministic episodes per environment and morphology at each evaluation."""

    eval_envs: int = 0
    """Environments per morphology of an evaluation, its episodes side by side. 0: the
    collection's (``num_envs``), through the collection's program; N > 0: a program of
    its own (one more to compile), so that an evaluation's cost does not grow with
    ``num_envs``."""

    checkpoint_every: int = 100_000
    """Counted env steps between checkpoints (0: only at the end)."""

    keep_checkpoints: int = 2
    """How many of the latest checkpoints are kept on disk."""

    time_limit: float = 0.0
    """Wall seconds for this process's rounds, compile and evaluations included; the first
    round that ends past them is evaluated and checkpointed and the run stops short of
    ``total_steps`` (``resume=RUN_DIR`` continues it). For runs compared at equal wall time
    and for batch jobs with a wall limit. 0: none."""

    tensorboard: bool = False
    """Also write TensorBoard event files in ``RUN_DIR/tensorboard`` (needs the
    ``tensorboard`` extra: ``pip install -e ".[tensorboard]"``)."""

    progress: bool = True
    """Show a progress bar on stderr."""

    plots: bool = True
    """Write the learning-curve and synergy figures to RUN_DIR/plots after evaluations (at
    most once a minute, ``viz.report.REDRAW_EVERY_S``) and at the end (``python -m
    solar_jax.plot`` compares runs)."""

    dry_run: bool = False
    """Build the suite, networks and replay, print the plan (sizes, parameter counts,
    replay memory) and exit without compiling or training."""

    network: NetworkConfig = NetworkConfig()
    """The network's sizes; left at the defaults, ``net``'s preset."""

    env: EnvConfig = EnvConfig()
    td3: TD3Config = TD3Config()

    def __post_init__(self):
        check_numbers(self)
        if self.method not in METHODS:
            raise ValueError(f"method={self.method}: expected one of {', '.join(METHODS)}")
        preset = NetworkConfig.preset(self.net)  # checks the name
        if self.network == NetworkConfig():  # the one place a preset is resolved
            object.__setattr__(self, "network", preset)
        if self.total_steps < 1:
            raise ValueError(f"total_steps must be >= 1, got {self.total_steps}")
        if self.total_steps > MAX_TOTAL_STEPS:  # a round past it must not wrap the counter
            raise ValueError(f"total_steps must be <= {MAX_TOTAL_STEPS:,}, got {self.total_steps}")
        if self.seed < 0:
            raise ValueError(f"seed must be >= 0, got {self.seed}")
        for name in (
            "num_envs",
            "eval_episodes",
            "keep_checkpoints",
            "delta_q_samples",
            "synergy_buckets",
        ):
            if getattr(self, name) < 1:
                raise ValueError(f"{name} must be >= 1, got {getattr(self, name)}")
        if self.round_steps and not self.replay_continued:
            raise ValueError(
                "replay_continued=false applies to episode rounds only (round_steps=0): "
                f"rounds of {self.round_steps} steps store every transition"
            )
        for name in (
            "replay_capacity",
            "round_steps",
            "eval_envs",
            "eval_every",
            "checkpoint_every",
            "time_limit",
        ):
            if getattr(self, name) < 0:
                raise ValueError(f"{name} must be >= 0, got {getattr(self, name)}")


def config_to_dict(config) -> dict:
    """A config as plain JSON-able data (nested dicts, tuples as lists)."""
    return dataclasses.asdict(config)


def _typed(key: str, value, kind):
    """``value`` (read from JSON) as a field of type ``kind``; a ``ValueError`` naming
    ``key`` when it is not one."""
    origin, args = typing.get_origin(kind), typing.get_args(kind)
    if origin in (typing.Union, types.UnionType):
        if value is None and type(None) in args:
            return None
        return _typed(key, value, next(k for k in args if k is not type(None)))
    if origin is typing.Literal:
        if value not in args:
            raise ValueError(f"{key}={value!r}: expected one of {', '.join(map(str, args))}")
        return value
    if origin is tuple:
        if not isinstance(value, list | tuple):
            raise ValueError(f"{key}={value!r}: expected a list")
        return tuple(_typed(f"{key}[{i}]", item, args[0]) for i, item in enumerate(value))
    ok = {
        bool: isinstance(value, bool),
        int: isinstance(value, int) and not isinstance(value, bool),
        float: isinstance(value, int | float) and not isinstance(value, bool),
        str: isinstance(value, str),
    }
    if not ok.get(kind, False):
        raise ValueError(f"{key}={value!r}: expected {getattr(kind, '__name__', kind)}")
    return float(value) if kind is float else value


def config_from_dict(cls, data: dict, prefix: str = ""):
    """The inverse of ``config_to_dict``; an unknown key, a value of the wrong type or out
    of range raises ``ValueError`` naming it (``prefix``: where ``cls`` sits, e.g. ``td3.``)."""
    if not isinstance(data, dict):
        raise ValueError(f"{prefix.rstrip('.') or 'config'}: expected a mapping, got {data!r}")
    hints = typing.get_type_hints(cls)
    fields = {f.name for f in dataclasses.fields(cls)}
    unknown = set(data) - fields
    if unknown:
        unknown = sorted(prefix + key for key in unknown)
        raise ValueError(f"unknown {cls.__name__} keys {unknown}; valid: {sorted(fields)}")
    values = {}
    for name, value in data.items():
        kind = hints[name]
        if dataclasses.is_dataclass(kind):
            values[name] = config_from_dict(kind, value, f"{prefix}{name}.")
        else:
            values[name] = _typed(prefix + name, value, kind)
    return cls(**values)
