"""Benchmark: cluster all 17 whh++ robots in one jitted, vmapped call vs scikit-learn.

    python benchmarks/affinity.py [repeats=50] [out=PATH]
    python -m benchmarks.affinity

The JAX side runs affinity propagation and the torso rule (algorithm.md §3) on every
robot at once, padded to N_max = 9, in float32 (the default dtype) and float64 (under
``jax.enable_x64``: scikit-learn's arithmetic, bit for bit). The host side loops
``sklearn.cluster.AffinityPropagation(affinity="precomputed", random_state=0)`` over the
robots. Both use the median preference of the first clustering. Timings exclude
compilation, which is reported separately. Writes JSON to
``benchmarks/results/affinity_<device>.json`` unless ``out=`` says otherwise.
"""

import json
import os
import platform
import statistics
import sys
import time
import warnings
from pathlib import Path

if __package__ in (None, ""):  # run as a script: make the repository importable
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
    import solar_jax  # noqa: F401  (before jax: its settings for jaxlib's logs, XLA, MuJoCo)

import jax  # noqa: E402
import numpy as np  # noqa: E402
import sklearn  # noqa: E402
from sklearn.cluster import AffinityPropagation  # noqa: E402

from benchmarks.options import parse_options  # noqa: E402
from solar_jax.morphology import get_suite, load  # noqa: E402
from solar_jax.morphology.graph import hop_distances  # noqa: E402
from solar_jax.synergy import affinity_propagation, synergy_structure  # noqa: E402

RESULTS = Path(__file__).resolve().parent / "results"
# whh++ (algorithm.md §1): parents in pre-order, from the morphology registry.
WHH_PARENTS = {name: load(name).parents for name in get_suite("whh++").members}
N_MAX = max(len(parents) for parents in WHH_PARENTS.values())


def _affinities() -> tuple[np.ndarray, np.ndarray]:
    """exp(-D) in float64 ``[R, N_max, N_max]`` and masks ``[R, N_max]``."""
    sims = np.zeros((len(WHH_PARENTS), N_MAX, N_MAX))
    masks = np.zeros((len(WHH_PARENTS), N_MAX), bool)
    for r, parents in enumerate(WHH_PARENTS.values()):
        n = len(parents)
        sims[r, :n, :n] = np.exp(-hop_distances(parents))
        masks[r, :n] = True
    return sims, masks


def _time(fn, repeats: int) -> list[float]:
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        fn()
        times.append(time.perf_counter() - start)
    return times


def _bench_jax(sims, masks, dtype, repeats):
    """Compile time, run times and the labels of one vmapped call over all robots."""

    @jax.jit
    @jax.vmap
    def cluster(similarity, mask):
        clustering = affinity_propagation(similarity, None, mask)
        return clustering, synergy_structure(clustering, mask)

    with jax.enable_x64(dtype == np.float64):
        s, m = jax.device_put(sims.astype(dtype)), jax.device_put(masks)
        start = time.perf_counter()
        compiled = cluster.lower(s, m).compile()
        compile_s = time.perf_counter() - start
        out = jax.block_until_ready(compiled(s, m))  # warm-up
        times = _time(lambda: jax.block_until_ready(compiled(s, m)), repeats)
    clustering, _ = jax.device_get(out)
    return compile_s, times, clustering


def _bench_sklearn(sims, masks, repeats):
    def run():
        out = []
        for s, m in zip(sims, masks, strict=True):
            n = int(m.sum())
            ap = AffinityPropagation(affinity="precomputed", random_state=0)
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")  # walker_2 is scikit-learn's degenerate case
                out.append(ap.fit(s[:n, :n]))
        return out

    fits = run()
    return _time(run, repeats), fits


def _row(name, compile_s, times, agree):
    med = statistics.median(times)
    return {
        "method": name,
        "compile_s": compile_s,
        "median_ms": 1e3 * med,
        "min_ms": 1e3 * min(times),
        "per_robot_us": 1e6 * med / len(WHH_PARENTS),
        "same_as_sklearn": agree,
    }


DEFAULTS = dict(repeats="50", out="")


def main(argv=None) -> dict:
    o = parse_options(sys.argv[1:] if argv is None else argv, DEFAULTS, __doc__)
    repeats = int(o["repeats"])

    sims, masks = _affinities()
    sk_times, fits = _bench_sklearn(sims, masks, repeats)

    def agreement(clustering) -> int:
        same = 0
        for r, (fit, m) in enumerate(zip(fits, masks, strict=True)):
            n, k = int(m.sum()), int(clustering.num_clusters[r])
            same += bool(
                np.array_equal(clustering.labels[r, :n], fit.labels_)
                and np.array_equal(clustering.exemplars[r, :k], fit.cluster_centers_indices_)
            )
        return same

    rows = [_row("scikit-learn loop (host, float64)", None, sk_times, len(fits))]
    clusterings = {}
    for dtype in (np.float32, np.float64):
        compile_s, times, clustering = _bench_jax(sims, masks, dtype, repeats)
        name = f"JAX jit+vmap ({np.dtype(dtype).name})"
        rows.append(_row(name, compile_s, times, agreement(clustering)))
        clusterings[np.dtype(dtype).name] = clustering

    device = jax.devices()[0]
    result = {
        "benchmark": "affinity propagation + torso rule, all whh++ robots",
        "robots": len(WHH_PARENTS),
        "n_max": N_MAX,
        "preference": "median",
        "repeats": repeats,
        "device_kind": device.device_kind,
        "platform": device.platform,
        "cpu_count": os.cpu_count(),
        "load_average_1min": os.getloadavg()[0],  # the host may be shared
        "machine": platform.machine(),
        "jax_version": jax.__version__,
        "sklearn_version": sklearn.__version__,
        "numpy_version": np.__version__,
        "results": rows,
        "num_clusters": {
            name: {
                "sklearn": len(fit.cluster_centers_indices_),
                **{k: int(c.num_clusters[r]) for k, c in clusterings.items()},
            }
            for r, (name, fit) in enumerate(zip(WHH_PARENTS, fits, strict=True))
        },
    }

    header = f"{'method':<36} {'compile s':>9} {'median ms':>9} {'min ms':>8} {'µs/robot':>8}"
    print(f"{len(WHH_PARENTS)} whh++ robots, N_max {N_MAX}, {device.device_kind}", end="")
    print(f", jax {jax.__version__}, {repeats} repeats")
    print(header + f" {'= sklearn':>9}")
    for row in rows:
        compile_s = "-" if row["compile_s"] is None else f"{row['compile_s']:.2f}"
        print(
            f"{row['method']:<36} {compile_s:>9} {row['median_ms']:>9.3f} {row['min_ms']:>8.3f}"
            f" {row['per_robot_us']:>8.1f} {row['same_as_sklearn']:>6}/{len(WHH_PARENTS)}"
        )

    out = Path(o["out"] or RESULTS / f"affinity_{_slug(device.device_kind)}.json")
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(result, indent=2) + "\n")
    print(f"wrote {out}")
    return result


def _slug(text: str) -> str:
    return "".join(c if c.isalnum() else "_" for c in text.lower()).strip("_")


if __name__ == "__main__":
    main()
