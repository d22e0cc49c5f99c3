"""Time to the first update: ``python -m solar_jax.train morph=SUITE`` from a cold and
a warm persistent compilation cache.

    python benchmarks/startup.py [suites=humanoid++,whh++] [args=] [caches=cold,warm]
                                 [repo=.] [tag=NAME] [out=DIR]

Per suite, the README's command (``args``: extra ``key=value`` settings, comma-separated)
runs in a child process with ``SOLAR_JAX_CACHE`` pointing at a fresh empty folder
(``cold``), then again with that folder as the first run left it (``warm``), each with
``total_steps=1`` (one round; it then evaluates and saves as any run's end does, which
is not timed). From the child's own output and ``metrics.jsonl``, seconds since the
child started:

- ``compiling``: the line that announces compilation (imports, suite, networks, init);
- ``first step``: the first collected env step, after compilation (the line "compiled
  in") and the deterministic evaluation every fresh run starts with (its ``eval_s``);
- ``first update``: the first TD3 iteration, after the first round's collection
  (``collect_s``; its re-clustering and its first iteration, well under a second, are
  not added);
- ``first round``: the end of the first round, its collection and all its TD3
  iterations (``collect_s`` + ``train_s``).

``repo=PATH`` runs another checkout's code (its ``solar_jax``; e.g. a worktree of an
older commit, for a before/after table). Timings are wall clock on a machine that runs
nothing else. Prints a table and writes ``startup[_<tag>]_<device>.json`` into ``out``
(default ``benchmarks/results/``).
"""

import json
import os
import platform
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

if __package__ in (None, ""):  # run as a script: make the repository importable
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from benchmarks.options import parse_options  # noqa: E402

OPTIONS = {
    "suites": "humanoid++,whh++",
    "args": "",
    "caches": "cold,warm",
    "repo": ".",
    "tag": "",
    "out": "",
}
RESULTS = Path(__file__).resolve().parent / "results"
ONE_ROUND = ["total_steps=1", "progress=false", "plots=false"]


def run_train(repo: Path, suite: str, args: list[str], cache: Path, out: Path) -> dict:
    """One ``train`` child; the seconds of its milestones (module docstring)."""
    command = [sys.executable, "-m", "solar_jax.train", f"morph={suite}", *args, *ONE_ROUND]
    command.append(f"out={out}")
    env = os.environ | {"SOLAR_JAX_CACHE": str(cache), "PYTHONPATH": str(repo)}
    start = time.perf_counter()
    lines = {}
    with subprocess.Popen(
        command, cwd=repo, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True
    ) as child:
        for line in child.stdout:
            now = time.perf_counter() - start
            for mark in ("compiling", "compiled in"):
                if line.startswith(mark) and mark not in lines:
                    lines[mark] = now
            backend = re.search(r"\) on (\w+):", line) if line.startswith("compiling") else None
            if backend:
                lines["backend"] = backend.group(1)
            print(f"  [{now:6.1f} s] {line}", end="", flush=True)
    if child.returncode != 0 or "compiled in" not in lines:
        raise RuntimeError(f"{' '.join(command)} failed (exit {child.returncode})")
    records = [json.loads(line) for line in (out / "metrics.jsonl").read_text().splitlines()]
    first_eval = next(r for r in records if r["kind"] == "eval")
    first_round = next(r for r in records if r["kind"] == "round")
    first_step = lines["compiled in"] + first_eval["perf/eval_s"]
    return {
        "backend": lines.get("backend", "unknown"),
        "compiling_s": lines["compiling"],
        "compile_s": lines["compiled in"] - lines["compiling"],
        "first_step_s": first_step,
        "first_update_s": first_step + first_round["perf/collect_s"],
        "first_round_s": first_step + first_round["perf/collect_s"] + first_round["perf/train_s"],
        "first_round": {k: first_round[k] for k in ("env_steps", "updates", "perf/train_s")},
        "wall_s": time.perf_counter() - start,
    }


def main(argv: list[str]) -> int:
    options = parse_options(argv, OPTIONS, __doc__)
    repo = Path(options["repo"]).resolve()
    args = [a for a in options["args"].split(",") if a]
    caches = options["caches"].split(",")
    rows = []
    with tempfile.TemporaryDirectory() as scratch:
        for suite in options["suites"].split(","):
            cache = Path(scratch) / f"cache-{suite}"
            cache.mkdir()
            for kind in caches:
                print(f"{suite}, {kind} cache:", flush=True)
                out = Path(scratch) / f"run-{suite}-{kind}"
                row = {"suite": suite, "cache": kind, **run_train(repo, suite, args, cache, out)}
                rows.append(row)
    print(f"repo {repo}, args {' '.join(args) or '-'}")
    print(
        "| suite | cache | compiling at s | compile s | first step s | first update s "
        "| first round s |"
    )
    print("|---|---|---:|---:|---:|---:|---:|")
    for r in rows:
        print(
            f"| {r['suite']} | {r['cache']} | {r['compiling_s']:.0f} | {r['compile_s']:.0f} "
            f"| {r['first_step_s']:.0f} | {r['first_update_s']:.0f} | {r['first_round_s']:.0f} |"
        )
    tag = f"_{options['tag']}" if options["tag"] else ""
    device = rows[0]["backend"] if rows else "none"
    results = Path(options["out"]) if options["out"] else RESULTS
    results.mkdir(parents=True, exist_ok=True)
    path = results / f"startup{tag}_{device}.json"
    meta = {
        "options": options,
        "machine": platform.machine(),
        "cpus": os.cpu_count(),
        "commit": _commit(repo),
    }
    path.write_text(json.dumps({"meta": meta, "rows": rows}, indent=1))
    print(f"-> {path}")
    return 0


def _commit(repo: Path) -> str:
    try:
        return subprocess.run(
            ["git", "-C", str(repo), "rev-parse", "--short", "HEAD"],
            capture_output=True,
            text=True,
            check=True,
        ).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return "unknown"


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
