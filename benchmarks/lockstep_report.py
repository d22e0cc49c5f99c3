"""The table and figure of the lockstep runs (``benchmarks/lockstep.py``).

    python benchmarks/lockstep_report.py [runs=benchmarks/results/lockstep]
        [figures=benchmarks/results/figures]

Prints a markdown table (one line per run: the worst ratio of ours's distance to the
float64 reference over the envelope, the envelope at the end, labels, saturation and
pre-tanh RMS at the end for ours and the reference in float32 and float64, and the
range of the nudged float32 runs) and writes
``lockstep.png``/``.svg``: per method and learning rate, against iterations, the actor
trunk's and the critics' distance to float64 (ours solid, the envelope dashed), and the
saturation and pre-tanh RMS (ours solid, float32 dashed, float64 dotted, the nudged
float32 runs thin), one colour per seed.
"""

import json
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:  # run as a script: make the repository importable
    sys.path.insert(0, str(ROOT))

from benchmarks.options import parse_options  # noqa: E402
from solar_jax.viz.figures import colour, new_figure, save  # noqa: E402

DEFAULTS = dict(
    runs=str(ROOT / "benchmarks" / "results" / "lockstep"),
    figures=str(ROOT / "benchmarks" / "results" / "figures"),
)
STYLES = {"ours": "-", "ref32": "--", "ref64": ":"}


def load_runs(folder: Path) -> list[dict]:
    runs = [json.loads(p.read_text()) for p in sorted(folder.glob("*.json"))]
    return sorted(runs, key=lambda r: (data(r) != "uniform", *arm(r), r["seed"]))


def data(run: dict) -> str:
    """ "uniform" (random transitions) or the replay file's name."""
    return Path(run.get("data", "uniform")).stem


def arm(run: dict) -> tuple:
    return run["method"] != "solar", -run["lr"], data(run)


def variants(row: dict) -> list[str]:
    """The nudged float32 reference runs of a row (``ref32_1``, ...)."""
    return [k for k in row if k.startswith("ref32_")]


def table(runs: list[dict]) -> str:
    lines = [
        "| method | lr | data | seed | worst ours / envelope (group)"
        " | envelope at end, trunk / critic | labels equal"
        " | saturation at end: ours / f32 / f64"
        " | pre-tanh RMS at end: ours / f32 / f64 (nudged f32 runs) | inside |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in runs:
        v, last = r["verdict"], r["rows"][-1]
        group = max(v["worst_ratio"], key=v["worst_ratio"].get)
        sat = " / ".join(f"{last[k]['saturation']:.3f}" for k in STYLES)
        rms = " / ".join(f"{last[k]['pre_tanh_rms']:.2f}" for k in STYLES)
        nudged = [last[k]["pre_tanh_rms"] for k in variants(last)]
        if nudged:
            rms += f" ({min(nudged):.2f}-{max(nudged):.2f})"
        lines.append(
            f"| {r['method']} | {r['lr']:g} | {data(r)} | {r['seed']}"
            f" | {v['worst_ratio'][group]:.2f} ({group})"
            f" | {last['envelope']['trunk']:.1e} / {last['envelope']['critic']:.1e}"
            f" | {'yes' if v['labels_equal'] else 'NO'} | {sat} | {rms}"
            f" | {'yes' if v['inside'] else 'NO'} |"
        )
    return "\n".join(lines)


def figure(runs: list[dict], out: Path) -> list[Path]:
    arms = sorted({arm(r) for r in runs})
    fig, axes = new_figure(len(arms), 4, (3.2, 2.2))
    for row, key in enumerate(arms):
        mine = [r for r in runs if arm(r) == key]
        method, lr = mine[0]["method"], mine[0]["lr"]
        if data(mine[0]) != "uniform":
            method = f"{method} ({data(mine[0])})"
        for i, r in enumerate(mine):
            c = colour(i, len(mine))
            its = [x["iteration"] for x in r["rows"]][1:]
            rows = r["rows"][1:]
            for col, group in enumerate(("trunk", "critic")):
                ax = axes[row, col]
                ax.semilogy(its, [x["ours"]["distance"][group] for x in rows], "-", color=c)
                ax.semilogy(its, [x["envelope"][group] for x in rows], "--", color=c)
                ax.set_title(f"{method} lr {lr:g}: {group} distance to f64", fontsize=8)
            for col, key in ((2, "saturation"), (3, "pre_tanh_rms")):
                ax = axes[row, col]
                for who in variants(rows[-1]):
                    ax.plot(its, [x[who][key] for x in rows], "-", color=c, lw=0.5, alpha=0.5)
                for who, style in STYLES.items():
                    ax.plot(its, [x[who][key] for x in rows], style, color=c)
                ax.set_title(f"{method} lr {lr:g}: {key}", fontsize=8)
    for ax in axes[-1]:
        ax.set_xlabel("TD3 iteration")
    return save(fig, out, "lockstep")


def main(argv: list[str]) -> int:
    o = parse_options(argv, DEFAULTS, __doc__)
    runs = load_runs(Path(o["runs"]))
    if not runs:
        print(f"error: runs={o['runs']}: no lockstep results (*.json) there", file=sys.stderr)
        return 2
    print(table(runs))
    for path in figure(runs, Path(o["figures"])):
        print(f"-> {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
