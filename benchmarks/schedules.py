"""The fast schedule against the paper's, and the fast schedule's ablation.

    python benchmarks/schedules.py [rows=fast,paper] [seeds=0-7] [methods=solar,amorpheus]
        [jobs=1] [tag=NAME] [warm=true] [against=ROW] [key=value ...]

Every (row, seed) is its own ``python -m solar_jax.train`` process, as a user runs it:
its wall time counts the compile (from whatever the compilation cache holds; the first
run of a row on a machine compiles cold) and the evaluations. Rows:

    fast        schedule=fast (config.SCHEDULES)
    paper       the paper's schedule at the quickstart's learning rate (1e-3) and the
                budget it reaches in about the fast row's wall time on a 2-core CPU
    no-KEY      schedule=fast with one of its keys back at the paper's value, for each
                key the fast schedule sets (``rows=ablation``: all of them)
    ROW+KEY=VALUE[+KEY=VALUE ...]
                any of these with keys of its own on top (``fast+round_steps=64``)

``methods=`` runs every row with each method (rows ``fast/solar``, ``paper/amorpheus``,
...). ``time_limit=SECONDS`` (a train key) compares the rows at equal wall time: every run
stops after the first round past it (``total_steps`` then defaults to the paper's 10M,
the paper row's included).

Defaults: ``morph=hopper_3 net=tiny total_steps=100000 eval_every=10000``, and a replay
ring allocated whole (``replay_capacity``: the update compiled once; no row fills it, so
results are those of the growing ring). ``jobs=2`` runs two processes at a time: the
returns are the same (a run repeats bit for bit on one host), the wall times are not.

Columns: the final deterministic return per seed (per robot too, in the JSON and a
second table), how many end at 1,000 or more, the
mean with its 95% Student-t interval, the best evaluation's mean, wall seconds per run
(mean and largest) and its compile share; with ``against=ROW``, every other row's mean
minus ROW's and the 90% Welch interval of that difference. Writes
``benchmarks/results/schedules_<morph>[_tag]_<device>.json`` after every run;
``report=THAT_JSON`` prints a finished one again.
"""

import concurrent.futures
import dataclasses
import json
import subprocess
import sys
import threading
import time
from pathlib import Path

if __package__ in (None, ""):  # run as a script: make the repository importable
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
    import solar_jax  # noqa: F401  (before jax: its settings for jaxlib's logs, XLA, MuJoCo)

import jax  # noqa: E402
import numpy as np  # noqa: E402

from benchmarks.options import train_help  # noqa: E402
from solar_jax.bench.common import machine  # noqa: E402
from solar_jax.cli import parse_config  # noqa: E402
from solar_jax.config import SCHEDULES, ConfigError, TrainConfig, config_to_dict  # noqa: E402
from solar_jax.stats import mean_ci, welch_interval  # noqa: E402
from solar_jax.training.logger import read_metrics  # noqa: E402
from solar_jax.training.rundir import flatten  # noqa: E402
from solar_jax.viz.curves import wall_seconds  # noqa: E402

DEFAULTS = [
    "morph=hopper_3",
    "net=tiny",
    "total_steps=100000",
    "eval_every=10000",
    "checkpoint_every=0",
    "progress=false",
    "plots=false",
    "replay_capacity=262144",
]
SOLVED = 1000.0  # a hopper that stays up for the whole 1,000-step episode scores about this
PAPER_STEPS = 50_000  # the paper schedule's counted steps in about the fast row's wall time


def _paper_value(key: str) -> str:
    """``key``'s value in the paper's schedule (TrainConfig's default), as key=value text."""
    value = flatten(config_to_dict(TrainConfig()))[key]
    return "none" if value is None else str(value)


def all_rows(timed: bool = False) -> dict[str, list[str]]:
    """Every row's keys; ``timed`` (``time_limit`` given): the paper row's budget is the
    time limit, not ``PAPER_STEPS``."""
    rows = {
        "fast": ["schedule=fast"],
        "paper": ["schedule=paper", "td3.lr=1e-3"]
        + ([] if timed else [f"total_steps={PAPER_STEPS}"]),
    }
    for key in SCHEDULES["fast"]:
        rows[f"no-{key}"] = ["schedule=fast", f"{key}={_paper_value(key)}"]
    return rows


def crossed(rows: dict[str, list[str]], methods: list[str]) -> dict[str, list[str]]:
    """Each row once per method, named ``row/method`` (no methods given: the rows as
    they are)."""
    if not methods:
        return rows
    return {f"{n}/{m}": [*keys, f"method={m}"] for n, keys in rows.items() for m in methods}


@dataclasses.dataclass
class Run:
    row: str
    seed: int
    final: float
    best: float
    env_steps: int
    updates: int
    wall_s: float
    compile_s: float
    curve: list = dataclasses.field(default_factory=list)
    """[[counted env steps, the run's own wall seconds, deterministic return], ...] at
    each evaluation (``viz.curves.wall_seconds``: compiles, rounds, evaluations)."""
    episodes: list = dataclasses.field(default_factory=list)
    """The same per round, of its training episodes' mean return (the paper's curves)."""
    robots: dict = dataclasses.field(default_factory=dict)
    """Each training robot's final deterministic return."""


def run_one(row: str, argv: list[str], seed: int, out: Path) -> Run:
    run_dir = out / row / f"seed{seed}"
    command = [sys.executable, "-m", "solar_jax.train", *argv, f"seed={seed}", f"out={run_dir}"]
    start = time.perf_counter()
    done = subprocess.run(command, capture_output=True, text=True)
    wall = time.perf_counter() - start
    if done.returncode != 0:
        raise RuntimeError(f"{row} seed {seed}: {done.stderr.strip().splitlines()[-1:]}")
    records = read_metrics(run_dir)
    evals = [r for r in records if r["kind"] == "eval"]
    walls = wall_seconds(records)

    def points(kind: str, key: str) -> list:
        pairs = zip(records, walls, strict=True)
        return [[r["env_steps"], float(w), r[key]] for r, w in pairs if r["kind"] == kind]

    return Run(
        row=row,
        seed=seed,
        final=evals[-1]["eval/train_return"],
        best=max(r["eval/train_return"] for r in evals[1:]),
        env_steps=records[-1]["env_steps"],
        updates=max(r.get("updates", 0) for r in records),
        wall_s=wall,
        compile_s=sum(r.get("perf/compile_s", 0.0) for r in records),
        curve=points("eval", "eval/train_return"),
        episodes=points("round", "episode/train_return"),
        robots={
            key.split("/")[1]: value
            for key, value in evals[-1].items()
            if key.startswith("eval/") and key.endswith("/return")
        },
    )


def summarise(runs: list[Run]) -> dict:
    finals = np.asarray([r.final for r in runs])
    mean, low, high = mean_ci(finals[:, None])
    walls = [r.wall_s for r in runs]
    return {
        "seeds": len(runs),
        "solved": int(np.sum(finals >= SOLVED)),
        "mean": float(mean[0]),
        "ci95": [float(low[0]), float(high[0])],
        "best_mean": float(np.mean([r.best for r in runs])),
        "wall_mean_s": float(np.mean(walls)),
        "wall_max_s": float(np.max(walls)),
        "compile_mean_s": float(np.mean([r.compile_s for r in runs])),
        "env_steps_mean": float(np.mean([r.env_steps for r in runs])),
    }


def table(data: dict) -> str:
    lines = [
        "| row | final return per seed | ≥ 1,000 at the end | mean [95% CI] | best, mean "
        "| env steps | wall s per run, mean / max (compile) |",
        "|---|---|---:|---:|---:|---:|---:|",
    ]
    for row, runs in data["runs"].items():
        if not runs:
            continue
        runs = sorted((Run(**r) for r in runs), key=lambda r: r.seed)
        s = summarise(runs)
        seeds = ", ".join(f"{r.final:,.0f}" for r in runs)
        lines.append(
            f"| {row} | {seeds} | {s['solved']} of {s['seeds']} | {s['mean']:,.0f} "
            f"[{s['ci95'][0]:,.0f}, {s['ci95'][1]:,.0f}] | {s['best_mean']:,.0f} | "
            f"{s['env_steps_mean']:,.0f} | {s['wall_mean_s']:.0f} / {s['wall_max_s']:.0f} "
            f"({s['compile_mean_s']:.0f}) |"
        )
    return "\n".join(lines)


def robots_table(data: dict) -> str:
    """Each row's final return per robot, mean over its seeds."""
    rows = {row: [Run(**r) for r in runs] for row, runs in data["runs"].items() if runs}
    if not rows or not next(iter(rows.values()))[0].robots:
        return ""
    names = list(next(iter(rows.values()))[0].robots)
    lines = [f"| row | {' | '.join(names)} |", "|---|" + "---:|" * len(names)]
    for row, runs in rows.items():
        means = [np.mean([r.robots[n] for r in runs]) for n in names]
        lines.append(f"| {row} | {' | '.join(f'{m:,.0f}' for m in means)} |")
    return "\n".join(lines)


def differences(data: dict, against: str) -> str:
    """Each row's mean final return minus row ``against``'s, with the 90% Welch interval
    of the difference (rows of fewer than two seeds are left out)."""
    finals = {row: np.asarray([r["final"] for r in runs]) for row, runs in data["runs"].items()}
    if len(finals.get(against, ())) < 2:
        raise ValueError(f"against={against}: expected a row of two or more seeds")
    lines = [f"| row | minus {against}: mean [90% Welch interval] |", "|---|---:|"]
    for row, values in finals.items():
        if row != against and len(values) >= 2:
            low, high = welch_interval(values, finals[against])
            diff = values.mean() - finals[against].mean()
            lines.append(f"| {row} | {diff:+,.0f} [{low:+,.0f}, {high:+,.0f}] |")
    return "\n".join(lines)


def report(data: dict, against: str | None) -> str:
    """The tables: per seed, per robot, and the differences to row ``against``."""
    parts = [table(data), robots_table(data)]
    if against:
        parts.append(differences(data, against))
    return "\n\n".join(p for p in parts if p)


def resolve_rows(names: list[str], base: dict[str, list[str]]) -> dict[str, list[str]]:
    """Each named row's keys: a base row's, and for ``ROW+KEY=VALUE+...`` its own on top;
    a ``ValueError`` naming the first row that is neither."""
    rows = {}
    for name in names:
        first, *extra = name.split("+")
        if first not in base or any("=" not in key for key in extra):
            raise ValueError(f"unknown row {name!r}; valid: {', '.join(base)}, or ROW+KEY=VALUE")
        rows[name] = [*base[first], *extra]
    return rows


def parse_seeds(text: str) -> list[int]:
    """``0-7`` or ``0,3,5``."""
    if "-" in text:
        first, last = text.split("-")
        return list(range(int(first), int(last) + 1))
    return [int(s) for s in text.split(",")]


OPTIONS = (
    ("rows=fast,paper", "list", "Rows: fast, paper, no-KEY, ablation, ROW+KEY=VALUE."),
    ("seeds=0-7", "range", "Seeds: a range 0-7 or a list 0,3,5."),
    ("methods=", "list", "Run every row with each method (rows named row/method)."),
    ("jobs=1", "int", "Runs at a time (wall times are comparable at 1 only)."),
    ("tag=", "str", "Names the results file schedules_<morph>_<tag>_<device>.json."),
    ("warm=false", "bool", "First a one-step run of each row: the timed runs load its programs."),
    ("report=", "path", "Print a finished run's JSON as a table."),
    ("against=", "str", "A row: every other row's difference to it, 90% Welch interval."),
)
OWN = ("rows=", "seeds=", "methods=", "jobs=", "tag=", "report=", "warm=", "against=")


def main(argv: list[str]) -> int:
    if train_help(argv, __doc__, OPTIONS, DEFAULTS):
        return 0
    own = {a.partition("=")[0]: a.partition("=")[2] for a in argv if a.startswith(OWN)}
    against = own.get("against") or None
    if "report" in own:
        data = json.loads(Path(own["report"]).read_text())
        try:
            print(report(data, against))
        except ValueError as err:
            print(f"error: {err}", file=sys.stderr)
            return 2
        return 0
    argv = [a for a in argv if not a.startswith(OWN)]
    given = {a.partition("=")[0] for a in argv}
    timed = "time_limit" in given  # equal wall time: the limit, not a step budget, ends runs
    defaults = [a for a in DEFAULTS if not (timed and a.startswith("total_steps="))]
    argv = [a for a in defaults if a.partition("=")[0] not in given] + argv
    base = all_rows(timed)
    names = own.get("rows", "fast,paper").split(",")
    if "ablation" in names:
        at = names.index("ablation")
        names[at : at + 1] = [n for n in base if n.startswith("no-")]
    try:
        rows = resolve_rows(names, base)
    except ValueError as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    methods = [m for m in own.get("methods", "").split(",") if m]
    rows = crossed(rows, methods)
    names = list(rows)
    if against and against not in names:
        print(f"error: against={against} is not a row; rows: {', '.join(names)}", file=sys.stderr)
        return 2
    seeds, jobs, tag = parse_seeds(own.get("seeds", "0-7")), int(own.get("jobs", 1)), ""
    if own.get("tag"):
        tag = "_" + own["tag"]
    try:  # every row's command line parses before anything runs
        for name in names:
            parse_config([*argv, *rows[name]])
    except (ConfigError, ValueError) as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    morph = next(a for a in argv if a.startswith("morph=")).removeprefix("morph=")
    out = Path(f"runs/schedules{tag}-{time.strftime('%Y%m%d-%H%M%S')}")
    device = jax.devices()[0].platform
    path = Path(__file__).parent / "results" / f"schedules_{Path(morph).stem}{tag}_{device}.json"
    meta = {"argv": argv, "rows": {n: rows[n] for n in names}, "jobs": jobs, "out": str(out)}
    meta["machine"] = machine()  # the device, host and versions; the commit measured
    data = {"meta": meta, "runs": {n: [] for n in names}}
    lock = threading.Lock()

    def one(name: str, seed: int):
        run = run_one(name, [*argv, *rows[name]], seed, out)
        with lock:
            data["runs"][name].append(dataclasses.asdict(run))
            path.write_text(json.dumps(data, indent=1))
        print(f"{name} seed {seed}: final {run.final:,.0f}, wall {run.wall_s:.0f} s", flush=True)

    def warm(name: str):  # compiles the row's programs into the cache, untimed
        argv_warm = [*argv, *rows[name], "total_steps=1", "time_limit=0", "plots=false"]
        command = [sys.executable, "-m", "solar_jax.train", *argv_warm]
        command.append(f"out={out / 'warm' / name}")
        done = subprocess.run(command, capture_output=True, text=True)
        if done.returncode != 0:
            raise RuntimeError(f"{name} warm-up: {done.stderr.strip().splitlines()[-1:]}")

    with concurrent.futures.ThreadPoolExecutor(jobs) as pool:
        if own.get("warm") == "true":
            for future in [pool.submit(warm, n) for n in names]:
                future.result()
            meta["warm"] = True  # every timed run loaded its programs from the cache
        for future in [pool.submit(one, n, s) for n in names for s in seeds]:
            future.result()
    print(report(data, against if len(seeds) > 1 else None))
    print(f"-> {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
