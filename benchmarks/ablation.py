"""The fidelity ablation: which of the reference's behaviours makes SOLAR learn.

    python benchmarks/ablation.py [rows=today,gate,init,all,amorpheus] [key=value ...]

Each row is one vmapped sweep (``solar_jax.sweep``, ``seeds`` lanes) of the same run,
with the switches that restore this project's earlier behaviour turned on or off:

    today      network.init=flax td3.gate_group=synergy network.torso_action=false
    gate       the gate in the actor's group only (init flax, torso zeroed)
    init       the reference's initialisation only (gate in the synergy group, torso zeroed)
    all        every change (the defaults)
    amorpheus  the baseline at the defaults, for the "learns as well as" comparison

Every row counts steps as the reference (L - 1 per episode), which has no switch.
Defaults: ``morph=hopper_3 net=tiny seeds=4 total_steps=30000 eval_every=2500``.
Columns: final deterministic return (mean, 95% Student-t interval over seeds, and each
seed's), the saturation share (|a| > 0.99) of the last round's policy, the wall time
(compilation apart). Prints a Markdown table and writes
``benchmarks/results/ablation_<morph>_<device>.json``.
"""

import json
import platform
import sys
import time
from pathlib import Path

if __package__ in (None, ""):  # run as a script: make the repository importable
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import jax  # noqa: E402
import numpy as np  # noqa: E402

from solar_jax.compilation_cache import enable_compilation_cache  # noqa: E402
from solar_jax.logger import read_metrics  # noqa: E402
from solar_jax.stats import mean_ci  # noqa: E402
from solar_jax.sweep import SweepRunner, parse_sweep  # noqa: E402

ROWS = {
    "today": ["network.init=flax", "td3.gate_group=synergy", "network.torso_action=false"],
    "gate": ["network.init=flax", "network.torso_action=false"],
    "init": ["td3.gate_group=synergy", "network.torso_action=false"],
    "all": [],
    "amorpheus": ["method=amorpheus"],
}
DEFAULTS = [
    "morph=hopper_3",
    "net=tiny",
    "seeds=4",
    "total_steps=30000",
    "eval_every=2500",
    "checkpoint_every=0",
    "progress=false",
]


def run_row(name: str, argv: list[str], out: Path) -> dict:
    sweep = parse_sweep([*argv, *ROWS[name], f"out={out / name}"])
    runner = SweepRunner(sweep)
    start = time.perf_counter()
    compile_s = []
    runner.lanes.compile = _timed(runner.lanes.compile, compile_s)
    runner.run()
    wall = time.perf_counter() - start
    finals, saturation, curves = [], [], []
    for spec in sweep.lanes:
        records = read_metrics(sweep.directory / spec.name)
        evals = [r for r in records if r["kind"] == "eval"]
        rounds = [r for r in records if r["kind"] == "round"]
        finals.append(evals[-1]["eval/train_return"])
        shares = [v for k, v in rounds[-1].items() if k.endswith("/saturated")]
        saturation.append(float(np.mean(shares)))
        curves.append([(r["env_steps"], r["eval/train_return"]) for r in evals])
    mean, low, high = mean_ci(np.asarray(finals)[:, None])
    return {
        "row": name,
        "switches": ROWS[name],
        "final_returns": finals,
        "mean": float(mean[0]),
        "ci95": [float(low[0]), float(high[0])],
        "saturated": saturation,
        "compile_s": compile_s[0] if compile_s else None,
        "wall_s": wall,
        "curves": curves,
    }


def _timed(fn, sink: list):
    def timed(*args):
        start = time.perf_counter()
        fn(*args)
        sink.append(time.perf_counter() - start)

    return timed


def table(rows: list[dict]) -> str:
    lines = [
        "| row | final deterministic return, mean [95% CI] | per seed | saturated "
        "| wall s (compile) |",
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


def main(argv: list[str]) -> int:
    rows = ROWS
    for arg in argv:
        if arg.startswith("rows="):
            rows = arg.removeprefix("rows=").split(",")
    unknown = [r for r in rows if r not in ROWS]
    if unknown:
        print(f"error: unknown rows {unknown}; valid: {', '.join(ROWS)}", file=sys.stderr)
        return 2
    argv = [a for a in argv if not a.startswith("rows=")]
    given = {arg.partition("=")[0] for arg in argv}
    argv = [a for a in DEFAULTS if a.partition("=")[0] not in given] + argv
    out = Path(f"runs/ablation-{time.strftime('%Y%m%d-%H%M%S')}")
    enable_compilation_cache()
    results = []
    for name in rows:
        results.append(run_row(name, argv, out))
        print(table(results[-1:]), flush=True)
    print(table(results))
    device = jax.devices()[0].platform
    morph = next(a for a in argv if a.startswith("morph=")).removeprefix("morph=")
    path = Path(__file__).parent / "results" / f"ablation_{morph}_{device}.json"
    meta = {"argv": argv, "device": device, "machine": platform.machine(), "out": str(out)}
    path.write_text(json.dumps({"meta": meta, "rows": results}, indent=1))
    print(f"-> {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
