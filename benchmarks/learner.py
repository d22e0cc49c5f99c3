"""The learner alone: TD3 iterations and samples per second without physics, as a share of
the machine's matrix-multiply rate.

    python benchmarks/learner.py [methods=solar] [presets=tiny,small,default]
                                 [robots=hopper_3,humanoid_2d_9_full] [updates=sequential,fused]
                                 [batch=100] [iterations=30] [repeats=3] [buckets=3]
                                 [tag=NAME]
                                 [reference=PATH/TO/Synergy-RL]

Rows: every method x robot x preset x update mode; a suite's name in ``robots`` stands for
its training morphologies (``robots=humanoid++ updates=fused``: the paper's fused update;
one fused row per suite, and one for the robots listed by name).
One jitted ``fori_loop`` of ``iterations`` TD3 iterations (critic every iteration, actor
and targets every 2nd, synergy module every 4th) on fixed random batches, compilation
timed apart, then the best of ``repeats`` timed calls:

- ``sequential``: ``agent.update`` on one robot's batch ``[B, N]`` (the reference's mode);
  samples per iteration = B.
- ``fused``: ``agent.fused_update`` on all the listed robots at once, each padded to the
  largest N (a suite's training morphologies); samples per iteration = M x B. One row per
  method and preset.

The networks run with the synergy slots the trainer gives the update
(``Trainer._in_slot_bucket``): the smallest of ``slot_buckets(N, buckets)`` holding the
robots' K (default: the trainer's ``synergy_buckets``; a list, ``buckets=1,3``, adds a
row per count; 1 is N slots, the padded update of commits before 2026-12-03).

FLOP/s is the model's work per iteration (XLA's cost analysis of the critic's and the
actor's loss gradients: critic + actor / policy_delay; optimiser arithmetic not counted)
over the measured time. Beside it, in the same run, the rate of two float32 GEMMs: the
update's typical shape ([B·N, width] x [width, feed-forward], per preset) and a large
square one (the machine's practical peak), so each figure reads as a fraction of what
this machine multiplies.

``reference=PATH`` adds the authors' PyTorch code (github.com/drdh/Synergy-RL, imported
as ``benchmarks/reference.py`` does; needs torch) for each sequential row of SOLAR or
Amorpheus, timed in turns with ours in the same process: its ``train_single`` on a
replay of random transitions at the same sizes, per iteration = (time of ``iterations``
iterations - time of 0) / ``iterations``, its ΔQ prologue given 1 sample instead of 1,000
(its cost is seconds, its noise larger than the iterations'), so the prologue is left out
as ours is. Its K is what that prologue's clustering gave (``reference_k``).
Prints a table and writes ``benchmarks/results/learner[_<tag>]_<device>.json``.
"""

import itertools
import json
import platform
import sys
import time
from pathlib import Path

if __package__ in (None, ""):  # run as a script: make the repository importable
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
    import solar_jax  # noqa: F401  (before jax: its settings for jaxlib's logs, XLA, MuJoCo)

import jax  # noqa: E402
import jax.numpy as jnp  # noqa: E402

from benchmarks.options import parse_options  # noqa: E402
from solar_jax.agent import Hyper, make_td3  # noqa: E402
from solar_jax.agent.state import join_actor, split_actor  # noqa: E402
from solar_jax.config import (  # noqa: E402
    NetworkConfig,
    TD3Config,
    TrainConfig,
)
from solar_jax.morphology import SUITES, get_suite, load  # noqa: E402
from solar_jax.networks import (  # noqa: E402
    OBS_SIZE,
    Structure,  # noqa: E402
    make_networks,
    pad_traversal,
)
from solar_jax.replay import Batch  # noqa: E402
from solar_jax.synergy import slot_bucket, slot_buckets  # noqa: E402
from solar_jax.synergy.discovery import SuiteAffinity  # noqa: E402

OPTIONS = {
    "methods": "solar",
    "presets": "tiny,small,default",
    "robots": "hopper_3,humanoid_2d_9_full",
    "updates": "sequential,fused",
    "batch": "100",
    "iterations": "30",
    "repeats": "3",
    "buckets": str(TrainConfig().synergy_buckets),
    "tag": "",
    "reference": "",
}
SQUARE = 1024  # the large GEMM's side
REFERENCE_DELTA_Q_SAMPLES = 1000  # the authors' train_single samples this many for ΔQ
RESULTS = Path(__file__).resolve().parent / "results"


def inputs(robots: list[str], batch: int, key: jax.Array) -> tuple[Batch, Structure]:
    """Random batches ``[M, B, ...]`` and the robots' structures ``[M, ...]`` (median
    clustering), every robot padded to the largest N."""
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
    structure = Structure(
        agent_mask=jnp.stack([jnp.arange(n) < len(m.parents) for m in morphs]),
        synergy=synergy,
        traversal=jnp.stack([pad_traversal(m.traversal, n) for m in morphs]),
    )
    return data, structure


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


def best_time(fn, args, repeats: int) -> float:
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


def reference_ms(
    root: str, method: str, preset: str, robot: str, batch: int, iterations: int, repeats: int
) -> tuple[float, list[int]]:
    """The authors' code: ms per TD3 iteration of ``train_single`` (see the docstring), and
    the K of each timed call's clustering (empty without synergies)."""
    import numpy as np
    import torch

    from benchmarks.reference import import_reference, reference_args

    arguments, utils, TD3 = import_reference(Path(root))
    morph = load(robot)
    n = len(morph.parents)
    args = reference_args(arguments, NetworkConfig.preset(preset), method)
    args.graphs = {robot: [[p] for p in morph.parents]}
    args.envs_train_names, args.envs_test_names = [robot], []
    args.agent_obs_size, args.max_action, args.max_num_agents = OBS_SIZE, 1.0, n
    args.max_children = utils.findMaxChildren([robot], args.graphs)
    torch.manual_seed(0)
    policy = TD3.TD3(args)
    policy.change_morphology(args.graphs[robot])
    policy.models2train()
    replay = utils.ReplayBuffer()
    rng = np.random.default_rng(0)
    for _ in range(2000):
        obs, next_obs = rng.normal(size=(2, n * OBS_SIZE)).astype(np.float32)
        replay.add((obs, next_obs, rng.uniform(-1, 1, n).astype(np.float32), rng.normal(), 0.0))

    class Replay:  # its ΔQ prologue's 1,000 samples as 1: seconds of noise out of the timing
        def sample(self, size: int):
            return replay.sample(1 if size == REFERENCE_DELTA_Q_SAMPLES else size)

    ks = []

    def train(count: int) -> float:
        start = time.perf_counter()
        policy.train_single(
            robot, Replay(), count, batch_size=batch, discount=args.discount, tau=args.tau,
            policy_noise=args.policy_noise, noise_clip=args.noise_clip,
            policy_freq=args.policy_freq, update_ac=True, update_sy=True,
        )  # fmt: skip
        seconds = time.perf_counter() - start
        centres = getattr(policy.synergy, "synergy_cluster_center", {}) if method == "solar" else {}
        if count and robot in centres:
            ks.append(len(centres[robot]))  # the clustering this call's iterations ran with
        return seconds

    train(2)  # warm-up
    with_updates = min(train(iterations) for _ in range(repeats))
    prologue = min(train(0) for _ in range(repeats))
    return 1000 * (with_updates - prologue) / iterations, ks


def measure(method, preset, robots, update, batch, iterations, repeats, buckets) -> dict:
    config = TD3Config(batch_size=batch)
    data, structure = inputs(robots, batch, jax.random.key(0))
    n = data.obs.shape[2]
    nets = make_networks(method, NetworkConfig.preset(preset), n_max=n)
    k = int(jnp.max(structure.synergy.num_synergies))
    sizes = slot_buckets(n, buckets) if nets.uses_synergy else (n,)
    slots = sizes[int(slot_bucket(structure.synergy.num_synergies, sizes))]  # the trainer's
    structure = structure.replace(synergy=structure.synergy.with_slots(slots))
    td3 = make_td3(nets, config)
    hyper = Hyper.from_config(config)
    if update == "sequential":
        data, structure = jax.tree.map(lambda x: x[0], (data, structure))
        step, morphs = td3.update, 1
    else:
        step, morphs = td3.fused_update, data.reward.shape[0]

    def run(state):
        def body(i, state):
            key = jax.random.fold_in(jax.random.key(1), i)
            state, _ = step(state, data, structure, i, key, hyper)
            return state

        return jax.lax.fori_loop(0, iterations, body, state)

    state = jax.jit(td3.init)(jax.random.key(1))
    start = time.perf_counter()
    compiled = jax.jit(run).lower(state).compile()
    compile_s = time.perf_counter() - start
    jax.block_until_ready(compiled(state))
    seconds = best_time(compiled, (state,), repeats) / iterations
    one = (
        (data, structure)
        if update == "sequential"
        else jax.tree.map(lambda x: x[0], (data, structure))
    )
    flops = morphs * model_flops(td3, config, state, *one, hyper)
    width = nets.config.width
    return {
        "method": method,
        "preset": preset,
        "robots": robots,
        "n": n,
        "update": update,
        "batch": batch,
        "synergy_buckets": buckets,
        "k": k,
        "slots": slots,
        "compile_s": compile_s,
        "ms_per_iteration": 1000 * seconds,
        "iterations_per_s": 1 / seconds,
        "samples_per_s": morphs * batch / seconds,
        "gflop_per_iteration": flops / 1e9,
        "gflop_per_s": flops / seconds / 1e9,
        "gemm_shape": [batch * n, width, nets.config.feedforward],
    }


def _reference_cells(row: dict) -> str:
    if "reference_ms_per_iteration" not in row:
        return "- | -"
    theirs = row["reference_ms_per_iteration"]
    ks = sorted(set(row["reference_k"]))
    k = f" (K {', '.join(map(str, ks))})" if ks else ""
    return f"{theirs:.1f}{k} | {theirs / row['ms_per_iteration']:.2f}x"


def main(argv: list[str]) -> int:
    options = parse_options(argv, OPTIONS, __doc__)
    batch, iterations, repeats = (int(options[k]) for k in ("batch", "iterations", "repeats"))
    names = options["robots"].split(",")
    suites = [get_suite(name).train for name in names if name in SUITES]
    robots = [name for name in names if name not in SUITES]
    bucket_counts = [int(count) for count in options["buckets"].split(",")]
    rows = []
    for method in options["methods"].split(","):
        for preset in options["presets"].split(","):
            for update in options["updates"].split(","):
                if update == "sequential":
                    groups = [[robot] for robot in robots + [r for suite in suites for r in suite]]
                else:  # each suite's training robots together; the listed robots together
                    groups = [list(suite) for suite in suites] + ([robots] if robots else [])
                for group, buckets in itertools.product(groups, bucket_counts):
                    row = measure(
                        method, preset, group, update, batch, iterations, repeats, buckets
                    )
                    row["gemm_gflop_per_s"] = gemm_rate(*row["gemm_shape"], repeats)
                    if options["reference"] and update == "sequential":
                        ms, ks = reference_ms(
                            options["reference"],
                            method,
                            preset,
                            group[0],
                            batch,
                            iterations,
                            repeats,
                        )
                        row["reference_ms_per_iteration"], row["reference_k"] = ms, ks
                    rows.append(row)
                    print(  # kept if a later one dies
                        f"measured {method} {preset} {update} {'+'.join(group)}: "
                        f"{row['ms_per_iteration']:.2f} ms / iteration, "
                        f"compile {row['compile_s']:.0f} s",
                        flush=True,
                    )
    peak = gemm_rate(SQUARE, SQUARE, SQUARE, repeats)
    device = jax.devices()[0].platform
    print(f"batch {batch}, {device}; square GEMM ({SQUARE}^3): {peak:.0f} GFLOP/s")
    print(
        "| method | robots (N) | preset | update | K / slots | ms / iteration | samples/s "
        "| GFLOP / it "
        "| GFLOP/s | GEMM of its shape, GFLOP/s | of square GEMM | compile s "
        "| reference ms / iteration | speed-up |"
    )
    print("|---|---|---|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
    for r in rows:
        print(
            f"| {r['method']} | {'+'.join(r['robots'])} ({r['n']}) | {r['preset']} "
            f"| {r['update']} | {r['k']} / {r['slots']} | {r['ms_per_iteration']:.1f} "
            f"| {r['samples_per_s']:,.0f} "
            f"| {r['gflop_per_iteration']:.2f} | {r['gflop_per_s']:.0f} "
            f"| {r['gemm_gflop_per_s']:.0f} | {r['gflop_per_s'] / peak:.0%} "
            f"| {r['compile_s']:.0f} | {_reference_cells(r)} |"
        )
    tag = f"_{options['tag']}" if options["tag"] else ""
    RESULTS.mkdir(parents=True, exist_ok=True)
    path = RESULTS / f"learner{tag}_{device}.json"
    meta = {
        "options": options,
        "device": device,
        "machine": platform.machine(),
        "square_gemm_gflop_per_s": peak,
        "jax": jax.__version__,
    }
    path.write_text(json.dumps({"meta": meta, "rows": rows}, indent=1))
    print(f"-> {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
