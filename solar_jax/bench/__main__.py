"""``python -m solar_jax.bench physics|learner|train|startup|all [key=value ...]``
(``solar_jax.bench``'s docstring); ``all`` runs the parts in turn on one config and
prints a summary: compile seconds, env steps/s and TD3 iterations/s of each."""

import dataclasses
import sys
import time
import traceback
import typing

from solar_jax.bench import __doc__ as PACKAGE_DOC
from solar_jax.bench import common, learner, physics, startup, train
from solar_jax.cli import HELP_FLAGS, plain
from solar_jax.config import TrainConfig

PARTS = {part.name: part for part in (physics.PART, learner.PART, train.PART, startup.PART)}
Name = typing.Literal["physics", "learner", "train", "startup"]


@dataclasses.dataclass(frozen=True)
class Options:
    parts: tuple[Name, ...] = ("physics", "learner", "train", "startup")
    """The parts to run, in this order, each with its own options' defaults."""
    rounds: int = 2
    """train's timed rounds (after one warm-up round)."""
    out: str = ""
    """The JSON's path; default ``bench_all_<device>.json`` here."""

    def __post_init__(self):
        if len(set(self.parts)) != len(self.parts) or not self.parts:
            raise ValueError(f"parts={','.join(self.parts)}: each part at most once")
        if self.rounds < 1:
            raise ValueError(f"rounds={self.rounds}: at least one round to time")


def part_options(name: str, options: Options):
    if name == "train":
        return dataclasses.replace(train.Options(), rounds=options.rounds, warmup_rounds=1)
    return PARTS[name].options


def run_all(config: TrainConfig, options: Options, config_argv=()) -> dict:
    """Each part in turn; one that fails is recorded with its error, the others still run."""
    parts = {}
    for name in options.parts:
        print(f"== {name}", flush=True)
        start = time.perf_counter()
        try:
            result, error = PARTS[name].run(config, part_options(name, options), config_argv), None
            print(PARTS[name].table(result), flush=True)
        except Exception:  # noqa: BLE001 - one part must not lose the others
            result, error = None, traceback.format_exc(limit=3)
            print(f"{name} failed:\n{error}", file=sys.stderr, flush=True)
        parts[name] = {"seconds": time.perf_counter() - start, "error": error, "result": result}
    return {"parts": parts}


DESCRIBE = {
    "physics": "{backend}, batch {batch}",
    "learner": "{method} {preset} {update} (N {n})",
    "train": "{update}, {lanes} lane(s)",
    "startup": "{cache} cache, first update at {first_update_s:.0f} s",
}


def summary_rows(result: dict) -> list[dict]:
    """One row per measured row of every part: what, compile s, env steps/s, iterations/s."""
    rows = []
    for name, part in result["parts"].items():
        if part["error"]:
            rows.append(dict(part=name, what="failed", compile="-", env="-", iterations="-"))
            continue
        for r in part["result"]["rows"]:
            what = DESCRIBE[name].format(**r)
            env = r.get("env_steps_per_s")
            iterations = r.get("iterations_per_s")
            rows.append(
                dict(
                    part=name,
                    what=what,
                    compile=f"{r['compile_s']:.1f}",
                    env="-" if env is None else f"{env:,.0f}",
                    iterations="-" if iterations is None else f"{iterations:,.1f}",
                )
            )
    return rows


def table_all(result: dict) -> str:
    columns = {
        "part": "{part}",
        "what": "{what}",
        "compile s": "{compile}",
        "env steps/s": "{env}",
        "TD3 iterations/s": "{iterations}",
    }
    return "summary\n" + common.markdown(columns, summary_rows(result))


def failed(result: dict) -> int:
    return 1 if any(part["error"] for part in result["parts"].values()) else 0


ALL = common.Part("all", PACKAGE_DOC, Options(), run_all, table_all, failed)


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    names = [*PARTS, "all"]
    if not argv or argv[0] in HELP_FLAGS:
        print(plain(PACKAGE_DOC.strip()))
        return 0 if argv else 2
    if argv[0] not in names:
        print(f"error: {argv[0]!r}: expected one of {', '.join(names)}", file=sys.stderr)
        return 2
    return common.main(ALL if argv[0] == "all" else PARTS[argv[0]], argv[1:])


if __name__ == "__main__":
    sys.exit(main())
