"""The learner beside the authors' code: ``python -m solar_jax.bench learner`` with the
reference's ms per TD3 iteration timed in turns with ours, in the same process.

    python benchmarks/learner.py reference=PATH/TO/Synergy-RL [methods=solar,amorpheus,smp]
        [amorpheus=PATH/TO/amorpheus] [presets=default]
        [robots=walker_7_main,humanoid_2d_9_full] [updates=sequential]
        [iterations=30] [repeats=3] [td3.batch_size=100] [key=value ...] [out=PATH]

Every key but ``reference`` and ``amorpheus`` is the bench part's (``python -m
solar_jax.bench learner --help``). For each sequential row of SOLAR or Amorpheus, the
authors' code (imported as ``benchmarks/reference.py`` does; needs torch) runs its
``train_single`` on a replay of random transitions at the same sizes: per iteration =
(time of ``iterations`` iterations - time of 0) / ``iterations``, its ΔQ prologue given
1 sample instead of 1,000 (its cost is seconds, its noise larger than the iterations'),
so the prologue is left out as ours is. Its K is what that prologue's clustering gave
(``reference_k``). For SMP, the Amorpheus code base's (``import_smp``: torchfold
batching the per-limb calls, on the CPU) at the reference's sizes whatever the preset,
in a process of its own started for the row (it cannot share one with Synergy-RL's
modules), timed the same way. Prints both tables and writes
``benchmarks/results/bench_learner_reference_<device>.json``.
"""

import concurrent.futures
import dataclasses
import multiprocessing
import sys
import time
from pathlib import Path

if __package__ in (None, ""):  # run as a script: make the repository importable
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
    import solar_jax  # noqa: F401  (before jax: its settings for jaxlib's logs, XLA, MuJoCo)

from solar_jax.bench import common, learner  # noqa: E402
from solar_jax.config import ConfigError, NetworkConfig  # noqa: E402
from solar_jax.morphology import load  # noqa: E402
from solar_jax.networks import OBS_SIZE  # noqa: E402

REFERENCE_DELTA_Q_SAMPLES = 1000  # the authors' train_single samples this many for ΔQ
RESULTS = Path(__file__).resolve().parent / "results"
REFERENCE_METHODS = ("solar", "amorpheus", "smp")


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


def smp_reference_ms(
    amorpheus: str, root: str, robot: str, batch: int, iterations: int, repeats: int
) -> float:
    """The Amorpheus code base's SMP (both passes, its ``scripts/smp_baseline``): ms per
    TD3 iteration of its ``train_single`` on random transitions (see the docstring)."""
    import numpy as np
    import torch

    from benchmarks.reference import import_smp

    utils, arguments, TD3 = import_smp(Path(amorpheus), Path(root))
    parents = list(load(robot).parents)
    sys.argv = ["main.py", "--td", "--bu", "--lr", "0.0001", "--batch_size", str(batch)]
    args = arguments.get_args()
    args.graphs, args.limb_obs_size, args.max_action = {robot: parents}, OBS_SIZE, 1.0
    args.max_children = utils.findMaxChildren([robot], args.graphs)
    torch.manual_seed(0)
    policy = TD3.TD3(args)
    policy.change_morphology(parents)
    policy.models2train()
    replay, n = utils.ReplayBuffer(), len(parents)
    rng = np.random.default_rng(0)
    for _ in range(2000):
        obs, next_obs = rng.normal(size=(2, n * OBS_SIZE)).astype(np.float32)
        replay.add((obs, next_obs, rng.uniform(-1, 1, n).astype(np.float32), rng.normal(), 0.0))

    def train(count: int) -> float:
        start = time.perf_counter()
        policy.train_single(
            replay, count, batch_size=batch, discount=args.discount, tau=args.tau,
            policy_noise=args.policy_noise, noise_clip=args.noise_clip,
            policy_freq=args.policy_freq,
        )  # fmt: skip
        return time.perf_counter() - start

    train(2)  # warm-up
    with_updates = min(train(iterations) for _ in range(repeats))
    prologue = min(train(0) for _ in range(repeats))
    return 1000 * (with_updates - prologue) / iterations


def _in_own_process(fn, *args):
    """``fn(*args)`` in a fresh interpreter (the references name their modules alike)."""
    context = multiprocessing.get_context("spawn")
    with concurrent.futures.ProcessPoolExecutor(1, mp_context=context) as pool:
        return pool.submit(fn, *args).result()


def with_reference(root: str, options: "Options"):
    """``learner.run``'s ``on_row``: the authors' timing added to each sequential row of a
    method they have."""

    def on_row(row: dict) -> None:
        if row["update"] != "sequential" or row["method"] not in REFERENCE_METHODS:
            return
        if row["method"] == "smp":
            row["reference_ms_per_iteration"] = _in_own_process(
                smp_reference_ms,
                options.amorpheus,
                root,
                row["robots"][0],
                row["batch"],
                options.iterations,
                options.repeats,
            )
            row["reference_k"] = []
        else:
            ms, ks = reference_ms(
                root,
                row["method"],
                row["preset"],
                row["robots"][0],
                row["batch"],
                options.iterations,
                options.repeats,
            )
            row["reference_ms_per_iteration"], row["reference_k"] = ms, ks

    return on_row


def table(result: dict) -> str:
    rows = [r for r in result["rows"] if "reference_ms_per_iteration" in r]
    for r in rows:
        ks = sorted(set(r["reference_k"]))
        r["reference_ks"] = ", ".join(map(str, ks)) or "-"
        r["speed_up"] = r["reference_ms_per_iteration"] / r["ms_per_iteration"]
    columns = {
        "method": "{method}",
        "robot": "{robots[0]} ({n})",
        "preset": "{preset}",
        "K / slots": "{k} / {slots}",
        "ms / iteration": "{ms_per_iteration:.2f}",
        "reference ms / iteration": "{reference_ms_per_iteration:.1f}",
        "reference K": "{reference_ks}",
        "speed-up": "{speed_up:.2f}x",
    }
    return learner.table(result) + "\nbeside the authors' code\n" + common.markdown(columns, rows)


@dataclasses.dataclass(frozen=True)
class Options(learner.Options):
    reference: str = ""
    """The authors' Synergy-RL checkout (required)."""
    amorpheus: str = ""
    """The Amorpheus checkout, for SMP's rows (required with ``methods=smp``)."""
    updates: tuple[learner.Update, ...] = ("sequential",)
    """Update modes; the authors' code has the sequential one."""


def run(config, options: Options, config_argv=()) -> dict:
    if not options.reference:
        raise ConfigError("reference=PATH (the authors' Synergy-RL checkout) is required")
    if "smp" in options.methods and not options.amorpheus:
        raise ConfigError("methods=smp needs amorpheus=PATH (the Amorpheus checkout)")
    on_row = with_reference(options.reference, options)
    return learner.run(config, options, config_argv, on_row=on_row)


PART = common.Part("learner_reference", __doc__, Options(), run, table)


def main(argv: list[str]) -> int:
    return common.main(PART, argv, results=RESULTS)


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
