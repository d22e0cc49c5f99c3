"""Compile time of the round's collection against the number of MJX worlds, per layout.

    python benchmarks/compile.py [suite=whh++] [worlds=1,2,4,8,17]
                                 [layouts=joint,per_world] [tag=NAME] [key=value ...]

For each count k and layout (``collect=joint``: every world in one program;
``per_world``: a program per world, compiled side by side), one child process builds
the trainer of the first k robots of ``suite`` (one world each) at the given
``TrainConfig`` settings (the paper's by default) and compiles the round's programs
ahead of time with no persistent cache (``RoundPrograms.compile``: the collection
programs, the replay's append and the update, as a run's first compile does). Reported:
the seconds to trace and lower the collection programs (one core, in turn), the wall
seconds of the whole compile, the slowest single collection program's XLA compile, and
the child's CPU seconds (user + sys) during the compile. Prints a table and writes
``benchmarks/results/compile[_<tag>]_<device>.json``.
"""

import json
import os
import platform
import resource
import subprocess
import sys
import time
from pathlib import Path

if __package__ in (None, ""):  # run as a script: make the repository importable
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from benchmarks.options import parse_options  # noqa: E402

OPTIONS = {"suite": "whh++", "worlds": "1,2,4,8,17", "layouts": "joint,per_world", "tag": ""}
RESULTS = Path(__file__).resolve().parent / "results"


def measure(suite: str, worlds: int, layout: str, settings: list[str]) -> dict:
    """In this process: the compile of the first ``worlds`` robots of ``suite``."""
    import jax

    from solar_jax.cli import parse_config
    from solar_jax.morphology import get_suite, suites
    from solar_jax.training.lanes import SingleLane
    from solar_jax.training.programs import RoundPrograms
    from solar_jax.training.trainer import Trainer

    members = get_suite(suite).members[:worlds]
    name = f"{suite}[:{worlds}]"
    suites.SUITES[name] = suites.Suite(name, members)
    config = parse_config([f"morph={name}", f"collect={layout}", *settings])
    trainer = Trainer(config)
    programs = RoundPrograms(SingleLane(trainer))
    state = jax.eval_shape(trainer.init, 0)
    cpu, start = _cpu(), time.perf_counter()
    programs.compile(state)
    wall, cpu = time.perf_counter() - start, _cpu() - cpu
    parts = [t for t in programs.compile_timings if t["name"].startswith("episodes")]
    return {
        "suite": suite,
        "worlds": worlds,
        "layout": layout,
        "robots": list(members),
        "programs": programs.compile_timings,
        "collection_lower_s": sum(t["lower_s"] for t in parts),
        "slowest_collection_compile_s": max(t["compile_s"] for t in parts),
        "compile_wall_s": wall,
        "compile_cpu_s": cpu,
        "backend": jax.default_backend(),
    }


def _cpu() -> float:
    usage = resource.getrusage(resource.RUSAGE_SELF)
    return usage.ru_utime + usage.ru_stime


def main(argv: list[str]) -> int:
    if argv and argv[0] == "--child":
        row = measure(argv[1], int(argv[2]), argv[3], argv[4:])
        print("ROW " + json.dumps(row), flush=True)
        return 0
    own = [a for a in argv if a.split("=")[0] in OPTIONS or a.startswith("-")]
    settings = [a for a in argv if a not in own]  # the trainer's key=value settings
    options = parse_options(own, OPTIONS, __doc__)
    rows = []
    env = os.environ | {"SOLAR_JAX_CACHE": "off"}
    for worlds in map(int, options["worlds"].split(",")):
        for layout in options["layouts"].split(","):
            command = [sys.executable, __file__, "--child", options["suite"], str(worlds), layout]
            child = subprocess.run(
                [*command, *settings], capture_output=True, text=True, env=env, check=False
            )
            row = next(
                (json.loads(line[4:]) for line in child.stdout.splitlines() if line[:4] == "ROW "),
                None,
            )
            if row is None:
                print(child.stdout[-2000:], child.stderr[-2000:], file=sys.stderr)
                raise RuntimeError(f"{worlds} worlds, {layout}: the child failed")
            rows.append(row)
            print(
                f"{worlds:>3} worlds {layout:>9}: trace+lower {row['collection_lower_s']:6.1f} s, "
                f"compile {row['compile_wall_s']:6.1f} s wall, {row['compile_cpu_s']:6.1f} CPU-s, "
                f"slowest collection program {row['slowest_collection_compile_s']:5.1f} s",
                flush=True,
            )
    print("| worlds | layout | trace + lower s | compile wall s | CPU-s | slowest program s |")
    print("|---:|---|---:|---:|---:|---:|")
    for r in rows:
        print(
            f"| {r['worlds']} | {r['layout']} | {r['collection_lower_s']:.1f} | "
            f"{r['compile_wall_s']:.1f} | {r['compile_cpu_s']:.0f} | "
            f"{r['slowest_collection_compile_s']:.1f} |"
        )
    tag = f"_{options['tag']}" if options["tag"] else ""
    backend = rows[0]["backend"] if rows else "none"
    RESULTS.mkdir(parents=True, exist_ok=True)
    path = RESULTS / f"compile{tag}_{backend}.json"
    meta = {"options": options, "settings": settings, "cpus": os.cpu_count()}
    meta |= {"machine": platform.machine()}
    path.write_text(json.dumps({"meta": meta, "rows": rows}, indent=1))
    print(f"-> {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
