"""The fidelity ablation: which of the reference's behaviours makes SOLAR learn.

    python benchmarks/ablation.py [rows=today,gate,init,all,amorpheus] [tag=NAME] [key=value ...]

Each row is the same run for ``seeds`` seeds, with the switches that restore this
project's earlier behaviour turned on or off:

    today      network.init=flax td3.gate_group=synergy network.torso_action=false
    gate       the gate in the actor's group only (init flax, torso zeroed)
    init       the reference's initialisation only (gate in the synergy group, torso zeroed)
    torso      the torso's action only (flax init, gate in the synergy group)
    all        every change (the defaults)
    amorpheus  the baseline at the defaults, for the "learns as well as" comparison
    monolithic the MLP baseline at the defaults
    smp        SMP at the defaults (its own: no gradient clip, ``METHOD_KEYS``)

Every row counts steps as the reference (L - 1 per episode), which has no switch.
Defaults: ``morph=hopper_3 net=tiny seeds=4 total_steps=30000 eval_every=2500``; ``tag=NAME``
names the results file ``ablation_<morph>_NAME_<device>.json``.

The seeds run one after another as single runs sharing one compiled trainer, not as one
vmapped sweep: a sweep's lanes are these runs (``tests/training/test_sweep.py``), and on a 2-core
CPU the 4-lane vmapped program measured 52 ms per env step against 4.2 ms for one run.
Columns: final deterministic return (mean, 95% Student-t interval over seeds, and each
seed's), the saturation share (|a| > 0.99) of the last round's policy, the wall time
(compilation apart); and the policy's health over training (saturated share, RMS of the
action before its tanh, RMS of the gate; ``metrics.jsonl``'s ``actions/*``). Prints
Markdown tables and writes ``benchmarks/results/ablation_<morph>_<device>.json``;
``report=THAT_JSON`` re-reads a finished ablation's run directories and prints them.
"""

import dataclasses
import json
import platform
import sys
import time
from pathlib import Path

if __package__ in (None, ""):  # run as a script: make the repository importable
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
    import solar_jax  # noqa: F401  (before jax: its settings for jaxlib's logs, XLA, MuJoCo)

import jax  # noqa: E402
import numpy as np  # noqa: E402

from benchmarks.options import train_help  # noqa: E402
from solar_jax.cli import parse_config  # noqa: E402
from solar_jax.stats import mean_ci  # noqa: E402
from solar_jax.training.logger import read_metrics  # noqa: E402
from solar_jax.training.programs import round_programs  # noqa: E402
from solar_jax.training.runner import Runner  # noqa: E402
from solar_jax.xla.cache import enable_compilation_cache  # noqa: E402

ROWS = {
    "today": ["network.init=flax", "td3.gate_group=synergy", "network.torso_action=false"],
    "gate": ["network.init=flax", "network.torso_action=false"],
    "init": ["td3.gate_group=synergy", "network.torso_action=false"],
    "torso": ["network.init=flax", "td3.gate_group=synergy"],
    "all": [],
    "amorpheus": ["method=amorpheus"],
    "monolithic": ["method=monolithic"],
    "smp": ["method=smp"],
}
DEFAULTS = [
    "morph=hopper_3",
    "net=tiny",
    "seeds=4",
    "total_steps=30000",
    "eval_every=2500",
    "checkpoint_every=0",
    "progress=false",
    "replay_capacity=100000",  # more than a row stores: the reference's 1e6 would not wrap
]


def run_row(name: str, argv: list[str], out: Path) -> dict:
    seeds = int(next(a for a in argv if a.startswith("seeds=")).removeprefix("seeds="))
    base = [a for a in argv if not a.startswith("seeds=")]
    config = parse_config([*base, *ROWS[name]])
    programs = round_programs(config)
    compile_s = []
    programs.compile = _timed(programs.compile, compile_s)
    start = time.perf_counter()
    finals, saturation, curves = [], [], []
    for seed in range(config.seed, config.seed + seeds):
        run_dir = out / name / f"seed{seed}"
        Runner(dataclasses.replace(config, seed=seed, out=str(run_dir)), programs).run()
        records = read_metrics(run_dir)
        evals = [r for r in records if r["kind"] == "eval"]
        rounds = [r for r in records if r["kind"] == "round"]
        finals.append(evals[-1]["eval/train_return"])
        shares = [v for k, v in rounds[-1].items() if k.endswith("/saturated")]
        saturation.append(float(np.mean(shares)))
        curves.append([(r["env_steps"], r["eval/train_return"]) for r in evals])
    wall = time.perf_counter() - start
    health = policy_health(
        [out / name / f"seed{s}" for s in range(config.seed, config.seed + seeds)]
    )
    mean, low, high = mean_ci(np.asarray(finals)[:, None])
    return {
        "row": name,
        "switches": ROWS[name],
        "final_returns": finals,
        "mean": float(mean[0]),
        "ci95": [float(low[0]), float(high[0])],
        "saturated": saturation,
        "compile_s": sum(compile_s),
        "wall_s": wall,
        "curves": curves,
        "health": health,
    }


HEALTH_MARKS = (2_500, 5_000, 10_000, 20_000, 30_000)
HEALTH = ("saturated", "pre_tanh_rms", "gate_rms")


def policy_health(run_dirs: list[Path]) -> dict:
    """{env steps mark: {diagnostic: mean over seeds}} from the last round at or before each
    mark: the share of saturated actions, the RMS before the tanh, the gate's RMS."""
    health = {}
    for mark in HEALTH_MARKS:
        per_seed = []
        for run_dir in run_dirs:
            rounds = [r for r in read_metrics(run_dir) if r["kind"] == "round"]
            before = [r for r in rounds if r["env_steps"] <= mark]
            if not before or rounds[-1]["env_steps"] < mark * 0.95:
                continue
            per_seed.append(
                {
                    d: np.mean([v for k, v in before[-1].items() if k.endswith(f"/{d}")])
                    for d in HEALTH
                }
            )
        if per_seed:
            health[mark] = {d: float(np.mean([p[d] for p in per_seed])) for d in HEALTH}
    return health


def health_table(rows: list[dict]) -> str:
    lines = [
        "| row | " + " | ".join(f"{m / 1000:g}k" for m in HEALTH_MARKS) + " |",
        "|---|" + "---:|" * len(HEALTH_MARKS),
    ]
    for r in rows:
        cells = []
        for mark in HEALTH_MARKS:
            h = r["health"].get(mark) or r["health"].get(str(mark))
            cells.append(
                "-"
                if h is None
                else f"{h['saturated']:.0%} / {h['pre_tanh_rms']:.1f} / {h['gate_rms']:.1f}"
            )
        lines.append(f"| {r['row']} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def _timed(fn, sink: list):
    def timed(*args):  # the trainer's compile: a dict lookup once its programs exist
        start = time.perf_counter()
        fn(*args)
        sink.append(time.perf_counter() - start)

    return timed


def table(rows: list[dict]) -> str:
    lines = [
        "| row | final deterministic return, mean [95% CI] | per seed | saturated "
        "| wall s, all seeds (compile) |",
        "|---|---:|---|---:|---:|",
    ]
    for r in rows:
        seeds = ", ".join(f"{v:.0f}" for v in r["final_returns"])
        low, high = r["ci95"]
        lines.append(
            f"| {r['row']} | {r['mean']:.0f} [{low:.0f}, {high:.0f}] | {seeds} | "
            f"{np.mean(r['saturated']):.0%} | {r['wall_s']:.0f} ({r['compile_s']:.0f}) |"
        )
    return "\n".join(lines)


def report(path: Path) -> int:
    """Re-reads a finished ablation (its JSON and run directories): both tables, and the
    policy's health written back into the JSON."""
    data = json.loads(path.read_text())
    out = Path(data["meta"]["out"])
    for row in data["rows"]:
        row["health"] = policy_health(sorted((out / row["row"]).glob("seed*")))
    path.write_text(json.dumps(data, indent=1))
    print(table(data["rows"]))
    print("\nsaturated share / pre-tanh RMS / gate RMS, mean over seeds\n")
    print(health_table(data["rows"]))
    return 0


OPTIONS = (
    ("rows=" + ",".join(ROWS), "list", "The rows to run (module docstring), in this order."),
    ("tag=", "str", "Names the results file ablation_<morph>_<tag>_<device>.json."),
    ("report=", "path", "Re-read a finished ablation's JSON and its run directories; print."),
)


def main(argv: list[str]) -> int:
    if train_help(argv, __doc__, OPTIONS, DEFAULTS):
        return 0
    for arg in argv:
        if arg.startswith("report="):
            return report(Path(arg.removeprefix("report=")))
    rows, tag = ROWS, ""
    for arg in argv:
        if arg.startswith("rows="):
            rows = arg.removeprefix("rows=").split(",")
        if arg.startswith("tag="):
            tag = "_" + arg.removeprefix("tag=")
    unknown = [r for r in rows if r not in ROWS]
    if unknown:
        print(f"error: unknown rows {unknown}; valid: {', '.join(ROWS)}", file=sys.stderr)
        return 2
    argv = [a for a in argv if not a.startswith(("rows=", "tag="))]
    given = {arg.partition("=")[0] for arg in argv}
    argv = [a for a in DEFAULTS if a.partition("=")[0] not in given] + argv
    # The tag in the name: two ablations started in the same second must not share runs.
    out = Path(f"runs/ablation{tag}-{time.strftime('%Y%m%d-%H%M%S')}")
    enable_compilation_cache()
    results = []
    for name in rows:
        results.append(run_row(name, argv, out))
        print(table(results[-1:]), flush=True)
    print(table(results))
    print("\nsaturated share / pre-tanh RMS / gate RMS, mean over seeds\n")
    print(health_table(results))
    device = jax.devices()[0].platform
    morph = next(a for a in argv if a.startswith("morph=")).removeprefix("morph=")
    path = Path(__file__).parent / "results" / f"ablation_{morph}{tag}_{device}.json"
    meta = {"argv": argv, "device": device, "machine": platform.machine(), "out": str(out)}
    path.write_text(json.dumps({"meta": meta, "rows": results}, indent=1))
    print(f"-> {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
