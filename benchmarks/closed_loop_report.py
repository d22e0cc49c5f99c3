"""Closed-loop equivalence of ours and the reference (``reference.py``'s runs, both arms
through the same loop, environment and evaluation).

    python benchmarks/closed_loop_report.py [runs=benchmarks/results/reference]
        [robot=hopper_3] [net=tiny] [method=solar] [margin=300] [min_seeds=14]
        [total_steps=30000] [out=PATH.json]

Per run, the primary metric is the mean deterministic return over the evaluations after
training started (every one but the step-0 evaluation). Per learning rate: the seeds
of each arm, their means, and the 90% Welch interval of ours minus the reference; the
two arms are equivalent within ±``margin`` (two one-sided tests at 5%) when that interval
lies inside [-margin, +margin], with at least ``min_seeds`` seeds per arm (fewer give
intervals too wide to mean much, and a lucky narrow one proves little). Beside it,
without gating: how many runs end at or above 1,000. Only seeds that both arms finished
are compared, and only runs that reached ``total_steps`` (a run still going, or killed,
is left out).
"""

import json
import re
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:  # run as a script: make the repository importable
    sys.path.insert(0, str(ROOT))

from benchmarks.options import parse_options  # noqa: E402
from solar_jax.stats import welch_interval  # noqa: E402

DEFAULTS = dict(
    runs=str(ROOT / "benchmarks" / "results" / "reference"),
    robot="hopper_3",
    net="tiny",
    method="solar",
    margin="300",
    min_seeds="14",
    total_steps="30000",
    out="",
)
SUCCESS = 1000.0


def load_arms(folder: Path, robot: str, net: str, method: str, total_steps: int) -> dict:
    """``{lr: {agent: {seed: [rows]}}}`` of the runs named by ``reference.py`` that
    reached ``total_steps``."""
    pattern = re.compile(
        rf"{re.escape(robot)}_{net}_{method}_lr(?P<lr>[^_]+)_(?P<agent>reference|ours)"
        r"_seed(?P<seed>\d+)\.jsonl"
    )
    arms: dict = {}
    for path in sorted(folder.glob("*.jsonl")):
        match = pattern.fullmatch(path.name)
        if match:
            rows = [json.loads(line) for line in path.read_text().splitlines() if line]
            if not rows or rows[-1]["env_steps"] < total_steps:
                continue
            lr, agent, seed = match["lr"], match["agent"], int(match["seed"])
            arms.setdefault(lr, {}).setdefault(agent, {})[seed] = rows
    return arms


def primary(rows: list[dict]) -> float:
    """Mean return over the evaluations after training started."""
    return float(np.mean([r["return"] for r in rows if r["env_steps"] > 0]))


def compare(arms: dict, margin: float, min_seeds: int = 14) -> list[dict]:
    out = []
    for lr, by_agent in sorted(arms.items(), key=lambda kv: -float(kv[0])):
        seeds = sorted(set(by_agent.get("ours", {})) & set(by_agent.get("reference", {})))
        row = {"lr": float(lr), "seeds": seeds}
        if len(seeds) >= 2:
            ours = np.array([primary(by_agent["ours"][s]) for s in seeds])
            ref = np.array([primary(by_agent["reference"][s]) for s in seeds])
            low, high = welch_interval(ours, ref)
            row |= {
                "ours": ours.tolist(),
                "reference": ref.tolist(),
                "ours_mean": float(ours.mean()),
                "reference_mean": float(ref.mean()),
                "interval_90": [low, high],
                "inside_margin": bool(-margin < low and high < margin),
                "equivalent": bool(-margin < low and high < margin and len(seeds) >= min_seeds),
                "success_ours": sum(by_agent["ours"][s][-1]["return"] >= SUCCESS for s in seeds),
                "success_reference": sum(
                    by_agent["reference"][s][-1]["return"] >= SUCCESS for s in seeds
                ),
            }
        out.append(row)
    return out


def verdict(row: dict) -> str:
    if row["equivalent"]:
        return "yes"
    if row["inside_margin"]:
        return f"inside, but {len(row['seeds'])} seeds are too few"
    return "not shown"


def table(rows: list[dict], margin: float) -> str:
    lines = [
        "| lr | seeds per arm | ours, mean | reference, mean | ours − reference, 90% interval"
        f" | equivalent within ±{margin:g} | ≥ 1,000 at the end: ours / reference |",
        "|---|---:|---:|---:|---|---|---|",
    ]
    for r in rows:
        if "interval_90" not in r:
            lines.append(f"| {r['lr']:g} | {len(r['seeds'])} | | | too few seeds | | |")
            continue
        low, high = r["interval_90"]
        lines.append(
            f"| {r['lr']:g} | {len(r['seeds'])} | {r['ours_mean']:.0f} | {r['reference_mean']:.0f}"
            f" | [{low:+.0f}, {high:+.0f}] | {verdict(r)}"
            f" | {r['success_ours']} / {r['success_reference']} |"
        )
    return "\n".join(lines)


def main(argv: list[str]) -> int:
    o = parse_options(argv, DEFAULTS, __doc__)
    margin = float(o["margin"])
    arms = load_arms(Path(o["runs"]), o["robot"], o["net"], o["method"], int(o["total_steps"]))
    if not arms:
        print(f"error: runs={o['runs']}: no runs of reference.py's naming there", file=sys.stderr)
        return 2
    rows = compare(arms, margin, int(o["min_seeds"]))
    print(table(rows, margin))
    if o["out"]:
        summary = {"margin": margin, "min_seeds": int(o["min_seeds"]), "arms": rows}
        Path(o["out"]).write_text(json.dumps(summary, indent=1) + "\n")
        print(f"-> {o['out']}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
