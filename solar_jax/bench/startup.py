"""Time to the first update: ``python -m solar_jax.train`` from a cold and a warm
persistent compilation cache.

    python -m solar_jax.bench startup morph=humanoid++ [caches=cold,warm] [repo=PATH]
        [key=value ...] [out=PATH]

``train`` with the given keys runs in a child process with ``SOLAR_JAX_CACHE`` pointing
at a fresh empty folder (``cold``), then again with that folder as the first run left it
(``warm``), each with ``total_steps=1`` (one round; the evaluation and save at its end
are not timed). From the child's output and ``metrics.jsonl``, seconds since the child
started:

- ``compiling at``: the line announcing compilation (imports, suite, networks, init);
- ``first step``: the first collected env step, after compilation and the
  deterministic evaluation every fresh run starts with;
- ``first update``: the first TD3 iteration, after the first round's collection;
- ``first round``: the end of the first round, its collection and TD3 iterations.

``repo=PATH`` runs another checkout's ``solar_jax`` (e.g. a worktree of an older commit,
for a before/after table). Wall clock: run it on a machine that runs nothing else.
"""

import dataclasses
import json
import os
import re
import subprocess
import sys
import tempfile
import time
import typing
from pathlib import Path

from solar_jax.bench.common import Part, commit, markdown
from solar_jax.config import TrainConfig

ONE_ROUND = ["total_steps=1", "progress=false", "plots=false"]


@dataclasses.dataclass(frozen=True)
class Options:
    caches: tuple[typing.Literal["cold", "warm"], ...] = ("cold", "warm")
    """Runs in order, sharing one cache folder: cold (empty), warm (as the last left it)."""
    repo: str = ""
    """Another checkout whose code to time; default this one."""
    out: str = ""
    """The JSON's path; default ``bench_startup_<device>.json`` here."""


def run_train(repo: Path, args: list[str], cache: Path, out: Path) -> dict:
    """One ``train`` child; the seconds of its milestones (module docstring)."""
    command = [sys.executable, "-m", "solar_jax.train", *args, *ONE_ROUND, f"out={out}"]
    env = os.environ | {"SOLAR_JAX_CACHE": str(cache), "PYTHONPATH": str(repo)}
    start = time.perf_counter()
    marks = {}
    with subprocess.Popen(
        command, cwd=repo, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True
    ) as child:
        for line in child.stdout:
            now = time.perf_counter() - start
            for mark in ("compiling", "compiled in"):
                if line.startswith(mark) and mark not in marks:
                    marks[mark] = now
            backend = re.search(r"\) on (\w+):", line) if line.startswith("compiling") else None
            if backend:
                marks["backend"] = backend.group(1)
            print(f"  [{now:6.1f} s] {line}", end="", flush=True)
    if child.returncode != 0 or "compiled in" not in marks:
        raise RuntimeError(f"{' '.join(command)} failed (exit {child.returncode})")
    records = [json.loads(line) for line in (out / "metrics.jsonl").read_text().splitlines()]
    first_eval = next(r for r in records if r["kind"] == "eval")
    first_round = next(r for r in records if r["kind"] == "round")
    first_step = marks["compiled in"] + first_eval["perf/eval_s"]
    first_update = first_step + first_round["perf/collect_s"]
    return {
        "backend": marks.get("backend", "unknown"),
        "compiling_s": marks["compiling"],
        "compile_s": marks["compiled in"] - marks["compiling"],
        "first_step_s": first_step,
        "first_update_s": first_update,
        "first_round_s": first_update + first_round["perf/train_s"],
        "first_round": {k: first_round[k] for k in ("env_steps", "updates", "perf/train_s")},
        "wall_s": time.perf_counter() - start,
    }


def run(config: TrainConfig, options: Options, config_argv=()) -> dict:
    repo = Path(options.repo or Path(__file__).resolve().parents[2]).resolve()
    args = [a for a in config_argv if not a.startswith("out=")]
    rows = []
    with tempfile.TemporaryDirectory() as scratch:
        cache = Path(scratch) / "cache-0"
        for i, kind in enumerate(options.caches):
            if kind == "cold":  # an empty folder; warm: the folder the last run left
                cache = Path(scratch) / f"cache-{i}"
            cache.mkdir(exist_ok=True)
            print(f"{config.morph}, {kind} cache:", flush=True)
            out = Path(scratch) / f"run-{i}"
            rows.append({"morph": config.morph, "cache": kind, **run_train(repo, args, cache, out)})
    return {"rows": rows, "repo": str(repo), "repo_commit": commit(repo), "args": args}


def table(result: dict) -> str:
    columns = {
        "morph": "{morph}",
        "cache": "{cache}",
        "compiling at s": "{compiling_s:.0f}",
        "compile s": "{compile_s:.0f}",
        "first step s": "{first_step_s:.0f}",
        "first update s": "{first_update_s:.0f}",
        "first round s": "{first_round_s:.0f}",
    }
    return markdown(columns, result["rows"])


PART = Part("startup", __doc__, Options(), run, table)
