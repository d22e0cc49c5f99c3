"""Re-clustering's cost per round: ΔQ and affinity propagation for every morphology.

    python benchmarks/recluster.py [suites=humanoid++,whh++] [net=default] [repeats=3]

Each round re-clusters every morphology of the suite, held-out ones too (algorithm.md §3):
ΔQ from ``delta_q_samples`` (1,000) replay samples, one forward pass of the first critic
over the N + 1 ablations of each, then affinity propagation, one morphology after
another in sorted-name order as ``update=sequential`` does. This times that loop alone,
as one jitted program over a replay of random transitions (what it reads does not change
its cost), and sets it beside the round's TD3 iterations at typical episode lengths L:
a round of L counted steps per morphology runs about L iterations per training
morphology (algorithm.md §5), at the learner's measured ms per iteration on the suite's
largest robot. The reference spends 4.2 s per morphology per round here at N = 9
(FINDINGS). Prints a table and writes ``benchmarks/results/recluster_<device>.json``.
"""

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
from solar_jax.bench import learner  # noqa: E402
from solar_jax.cli import parse_config  # noqa: E402
from solar_jax.training.trainer import Trainer  # noqa: E402

OPTIONS = {"suites": "humanoid++,whh++", "net": "default", "repeats": "3"}
EPISODE_LENGTHS = (100, 1000)
RESULTS = Path(__file__).resolve().parent / "results"


def random_replay(replay, key: jax.Array):
    """``replay`` filled to its capacity with random transitions."""
    obs_key, action_key = jax.random.split(key)
    full = jnp.full_like(replay.size, replay.capacity)
    return replay.replace(
        obs=jax.random.normal(obs_key, replay.obs.shape),
        action=jax.random.uniform(action_key, replay.action.shape, minval=-1, maxval=1),
        size=full,
    )


def measure(suite: str, net: str, repeats: int) -> dict:
    config = parse_config([f"morph={suite}", f"net={net}", "progress=false"])
    trainer = Trainer(config)
    state = trainer.init(0)
    state = state.replace(replay=random_replay(state.replay, jax.random.key(1)))
    key = jax.random.key(2)

    def recluster(state):
        def one(j, synergy):  # update=sequential's order: sorted names, held-out too
            morph = trainer.update_order[j]
            critic, replay = state.agent.critic, state.replay
            return trainer._recluster_one(
                critic, replay, synergy, morph, jax.random.fold_in(key, morph)
            )

        return jax.lax.fori_loop(0, trainer.num_morphs, one, state.synergy)

    start = time.perf_counter()
    compiled = jax.jit(recluster).lower(state).compile()
    compile_s = time.perf_counter() - start
    jax.block_until_ready(compiled(state))
    seconds = learner.best_time(compiled, (state,), repeats)
    # The round's updates: ~L iterations per training morphology, at the largest robot's cost
    # (collection not counted, so the shares are upper bounds).
    largest = max(
        trainer.names, key=lambda name: int(trainer.env.agent_mask[trainer.names.index(name)].sum())
    )
    timing = learner.Options(iterations=10, repeats=repeats)
    update = learner.measure(config, config.method, net, [largest], "sequential", timing)
    iteration_s = update["ms_per_iteration"] / 1000
    shares = {
        str(length): seconds / (seconds + trainer.num_train * length * iteration_s)
        for length in EPISODE_LENGTHS
    }
    return {
        "suite": suite,
        "net": net,
        "morphologies": trainer.num_morphs,
        "training": trainer.num_train,
        "n_max": trainer.env.n_max,
        "samples": config.delta_q_samples,
        "compile_s": compile_s,
        "s_per_round": seconds,
        "s_per_morphology": seconds / trainer.num_morphs,
        "largest_robot": largest,
        "ms_per_iteration": update["ms_per_iteration"],
        "share_of_round": shares,
    }


def main(argv: list[str]) -> int:
    options = parse_options(argv, OPTIONS, __doc__)
    rows = [
        measure(suite, options["net"], int(options["repeats"]))
        for suite in options["suites"].split(",")
    ]
    device = jax.devices()[0].platform
    print(f"net={options['net']}, {device}")
    lengths = " | ".join(f"share at L = {length}" for length in EPISODE_LENGTHS)
    print(
        "| suite | morphologies (train) | N_max | s / round | s / morphology "
        f"| ms / TD3 iteration | {lengths} | compile s |"
    )
    print("|---|---:|---:|---:|---:|---:|" + "---:|" * len(EPISODE_LENGTHS) + "---:|")
    for r in rows:
        shares = " | ".join(f"{r['share_of_round'][str(n)]:.1%}" for n in EPISODE_LENGTHS)
        print(
            f"| {r['suite']} | {r['morphologies']} ({r['training']}) | {r['n_max']} "
            f"| {r['s_per_round']:.2f} | {r['s_per_morphology']:.3f} "
            f"| {r['ms_per_iteration']:.1f} | {shares} | {r['compile_s']:.0f} |"
        )
    RESULTS.mkdir(parents=True, exist_ok=True)
    path = RESULTS / f"recluster_{device}.json"
    meta = {"options": options, "device": device, "machine": platform.machine()}
    path.write_text(json.dumps({"meta": meta, "rows": rows}, indent=1))
    print(f"-> {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
