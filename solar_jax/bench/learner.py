"""The learner alone: TD3 iterations and samples per second without physics, as a share of
this machine's matrix-multiply rate.

    python -m solar_jax.bench learner morph=humanoid++ [methods=solar,amorpheus]
        [presets=tiny,default] [updates=sequential,fused] [robots=hopper_3,walker++]
        [iterations=30] [repeats=3] [td3.batch_size=100] [out=PATH]

Rows: every method x preset x update mode x robot group. ``sequential`` runs
``agent.update`` on one robot's batch ``[B, N]`` (the reference's mode; samples per
iteration = B), one row per robot: the largest of the suite's training morphologies, or
each of ``robots`` (a suite's name there stands for its training morphologies).
``fused`` runs ``agent.fused_update`` on all the suite's training morphologies at once
(or all of ``robots``), each padded to the largest N (samples per iteration = M x B).

One jitted ``fori_loop`` of ``iterations`` TD3 iterations (critic every iteration, actor
and targets every ``td3.policy_delay``-th, synergy module every ``td3.synergy_delay``-th)
on fixed random batches, compilation timed apart, then the best of ``repeats`` calls.
The networks get the synergy slots the trainer gives them (the smallest of
``synergy_buckets`` buckets holding the robots' K). FLOP/s is the model's work per
iteration (XLA's cost analysis of the critic's and the actor's loss gradients; the
optimiser not counted) over the time; beside it, in the same run, the rate of two
float32 GEMMs: the update's typical shape ([B·N, width] x [width, feed-forward]) and a
1024-square one (the machine's practical peak).
"""

import dataclasses
import time
import typing
from collections.abc import Callable

import jax
import jax.numpy as jnp

from solar_jax.agent import Hyper, make_td3
from solar_jax.agent.state import join_actor, split_actor
from solar_jax.bench.common import Part, markdown
from solar_jax.config import Method, NetworkConfig, TD3Config, TrainConfig
from solar_jax.morphology import SUITES, get_suite, load
from solar_jax.networks import OBS_SIZE, Structure, limb_trees, make_networks, pad_traversal
from solar_jax.replay import Batch
from solar_jax.synergy import slot_bucket, slot_buckets
from solar_jax.synergy.discovery import SuiteAffinity

SQUARE = 1024  # the large GEMM's side
Preset = typing.Literal["default", "small", "tiny"]
Update = typing.Literal["sequential", "fused"]


@dataclasses.dataclass(frozen=True)
class Options:
    methods: tuple[Method, ...] = ()
    """Methods, one row each; none given: ``method``."""
    presets: tuple[Preset, ...] = ()
    """Network presets, one row each; none given: ``net``."""
    updates: tuple[Update, ...] = ("sequential", "fused")
    """Update modes: sequential (one robot's batch), fused (all robots' at once)."""
    robots: tuple[str, ...] = ()
    """Robots or suites instead of ``morph``'s training morphologies."""
    iterations: int = 30
    """TD3 iterations per timed call."""
    repeats: int = 3
    """Timed calls; the best is reported."""
    out: str = ""
    """The JSON's path; default ``bench_learner_<device>.json`` here."""

    def __post_init__(self):
        if self.iterations < 1 or self.repeats < 1:
            raise ValueError("learner: iterations and repeats must be >= 1")


def robot_groups(config: TrainConfig, options: Options, update: str) -> list[list[str]]:
    """The robots of each row of an update mode (module docstring)."""
    if options.robots:
        named = [r for r in options.robots if r not in SUITES]
        suites = [list(get_suite(r).train) for r in options.robots if r in SUITES]
        if update == "sequential":
            return [[r] for r in named + [r for suite in suites for r in suite]]
        return suites + ([named] if named else [])
    train = list(get_suite(config.morph).train)
    if update == "sequential":
        return [[max(train, key=lambda name: len(load(name).parents))]]
    return [train]


def inputs(robots: list[str], batch: int, key: jax.Array) -> tuple[Batch, Structure, tuple]:
    """Random batches ``[M, B, ...]``, the robots' structures ``[M, ...]`` (median
    clustering), every robot padded to the largest N, and the most children of any limb
    (SMP's networks)."""
    morphs = [load(robot) for robot in robots]
    n = max(len(m.parents) for m in morphs)
    count = len(morphs)
    keys = jax.random.split(key, 4)
    data = Batch(
        obs=jax.random.normal(keys[0], (count, batch, n, OBS_SIZE)),
        action=jax.random.uniform(keys[1], (count, batch, n), minval=-1, maxval=1),
        reward=jax.random.normal(keys[2], (count, batch)),
        next_obs=jax.random.normal(keys[3], (count, batch, n, OBS_SIZE)),
        terminated=jnp.zeros((count, batch), bool),
    )
    synergy = SuiteAffinity([m.parents for m in morphs], n).cluster()
    tree, children = limb_trees([m.parents for m in morphs], [m.name for m in morphs], n)
    structure = Structure(
        agent_mask=jnp.stack([jnp.arange(n) < len(m.parents) for m in morphs]),
        synergy=synergy,
        traversal=jnp.stack([pad_traversal(m.traversal, n) for m in morphs]),
        tree=tree,
    )
    return data, structure, children


def model_flops(td3, config: TD3Config, state, data: Batch, structure: Structure, hyper) -> float:
    """FLOPs of one average iteration of one morphology: the critic's loss gradient, plus
    the actor's (synergy module included) every ``policy_delay``-th iteration."""
    losses = td3.losses

    def critic(state):
        target = join_actor(state.target_actor, split_actor(state.actor, config)[1])
        return jax.grad(losses.critic, has_aux=True)(
            state.critic, target, state.target_critic, data, structure, jax.random.key(0), hyper
        )

    def actor(state):
        return jax.grad(losses.actor)(state.actor, state.critic, data, structure)

    def flops(fn) -> float:
        cost = jax.jit(fn).lower(state).compile().cost_analysis()
        cost = cost[0] if isinstance(cost, list) else cost
        return float(cost["flops"])

    return flops(critic) + flops(actor) / config.policy_delay


def best_time(fn: Callable, args: tuple, repeats: int) -> float:
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        jax.block_until_ready(fn(*args))
        times.append(time.perf_counter() - start)
    return min(times)


def gemm_rate(m: int, k: int, n: int, repeats: int) -> float:
    """GFLOP/s of float32 products ``[m, k] x [k, n]`` and back ``[m, n] x [n, k]`` (a
    feed-forward block's two), chained inside one program so that none is skipped."""
    reps = max(1, int(2e9 // (4 * m * k * n)))  # about 2 GFLOP per call
    keys = jax.random.split(jax.random.key(0), 3)
    x = jax.random.normal(keys[0], (m, k))
    up = jax.random.normal(keys[1], (k, n)) / k**0.5  # norms stay about constant
    down = jax.random.normal(keys[2], (n, k)) / n**0.5

    def chain(x, up, down):
        return jax.lax.fori_loop(0, reps, lambda i, x: (x @ up) @ down, x)

    compiled = jax.jit(chain).lower(x, up, down).compile()
    jax.block_until_ready(compiled(x, up, down))
    return 4 * m * k * n * reps / best_time(compiled, (x, up, down), repeats) / 1e9


def measure(
    config: TrainConfig, method: str, preset: str, robots: list[str], update: str, options: Options
) -> dict:
    """One row: ``update`` of ``method`` at ``preset`` on ``robots``."""
    td3_config = config.td3
    batch = td3_config.batch_size
    data, structure, max_children = inputs(robots, batch, jax.random.key(0))
    n = data.obs.shape[2]
    nets = make_networks(method, NetworkConfig.preset(preset), n, OBS_SIZE, max_children)
    k = int(jnp.max(structure.synergy.num_synergies))
    sizes = slot_buckets(n, config.synergy_buckets) if nets.uses_synergy else (n,)
    slots = sizes[int(slot_bucket(structure.synergy.num_synergies, sizes))]  # the trainer's
    structure = structure.replace(synergy=structure.synergy.with_slots(slots))
    td3 = make_td3(nets, td3_config)
    hyper = Hyper.from_config(td3_config)
    if update == "sequential":
        data, structure = jax.tree.map(lambda x: x[0], (data, structure))
        step, morphs = td3.update, 1
    else:
        step, morphs = td3.fused_update, data.reward.shape[0]

    def iterations(state):
        def body(i, state):
            key = jax.random.fold_in(jax.random.key(1), i)
            state, _ = step(state, data, structure, i, key, hyper)
            return state

        return jax.lax.fori_loop(0, options.iterations, body, state)

    state = jax.jit(td3.init)(jax.random.key(1))
    start = time.perf_counter()
    compiled = jax.jit(iterations).lower(state).compile()
    compile_s = time.perf_counter() - start
    jax.block_until_ready(compiled(state))
    seconds = best_time(compiled, (state,), options.repeats) / options.iterations
    one = (data, structure)
    if update == "fused":  # the FLOPs of one morphology's share, times M
        one = jax.tree.map(lambda x: x[0], one)
    flops = morphs * model_flops(td3, td3_config, state, *one, hyper)
    width = nets.config.width
    shape = [batch * n, width, nets.config.feedforward]
    return {
        "method": method,
        "preset": preset,
        "robots": robots,
        "n": n,
        "update": update,
        "batch": batch,
        "synergy_buckets": config.synergy_buckets,
        "k": k,
        "slots": slots,
        "compile_s": compile_s,
        "ms_per_iteration": 1000 * seconds,
        "iterations_per_s": 1 / seconds,
        "samples_per_s": morphs * batch / seconds,
        "gflop_per_iteration": flops / 1e9,
        "gflop_per_s": flops / seconds / 1e9,
        "gemm_shape": shape,
        "gemm_gflop_per_s": gemm_rate(*shape, options.repeats),
    }


def run(config: TrainConfig, options: Options, config_argv=(), on_row: Callable = None) -> dict:
    """Every row (module docstring); ``on_row(row)`` after each, e.g. to time another
    implementation in turns with ours."""
    rows = []
    for method in options.methods or (config.method,):
        for preset in options.presets or (config.net,):
            for update in options.updates:
                for robots in robot_groups(config, options, update):
                    row = measure(config, method, preset, robots, update, options)
                    if on_row is not None:
                        on_row(row)
                    rows.append(row)
                    print(  # kept if a later one dies
                        f"  measured {method} {preset} {update} {'+'.join(robots)}: "
                        f"{row['ms_per_iteration']:.2f} ms / iteration, "
                        f"compile {row['compile_s']:.1f} s",
                        flush=True,
                    )
    return {"rows": rows, "square_gemm_gflop_per_s": gemm_rate(SQUARE, SQUARE, SQUARE, 3)}


def table(result: dict) -> str:
    peak = result["square_gemm_gflop_per_s"]
    rows = [
        r | {"group": f"{'+'.join(r['robots'])} ({r['n']})", "share": r["gflop_per_s"] / peak}
        for r in result["rows"]
    ]
    columns = {
        "method": "{method}",
        "robots (N)": "{group}",
        "preset": "{preset}",
        "update": "{update}",
        "K / slots": "{k} / {slots}",
        "compile s": "{compile_s:.1f}",
        "ms / iteration": "{ms_per_iteration:.2f}",
        "iterations/s": "{iterations_per_s:,.1f}",
        "samples/s": "{samples_per_s:,.0f}",
        "GFLOP/s": "{gflop_per_s:.1f}",
        "GEMM of its shape, GFLOP/s": "{gemm_gflop_per_s:.0f}",
        "of square GEMM": "{share:.0%}",
    }
    return f"square GEMM ({SQUARE}^3): {peak:.0f} GFLOP/s\n" + markdown(columns, rows)


PART = Part("learner", __doc__, Options(), run, table)
