"""Experiment files: a paper experiment (or the quickstart) as one TOML file that
``train`` or ``sweep`` runs with one command, ``key=value`` overrides still on top::

    python -m solar_jax.sweep experiments/humanoid_multitask.toml [key=value ...]

A file holds::

    description = "what it reproduces"
    command = "sweep"              # or "train": the command that runs it
    expected = "steps and wall time, measured on CPU, and what a GPU needs"

    [config]                       # train's keys; dotted ones quoted: "td3.lr" = 3e-4
    morph = "humanoid++"
    seeds = 4                      # sweep only

    [variants.solar]               # optional: run one after another, each on top of
    method = "solar"               # [config], into <out>/<variant name>

An experiment without ``[variants]`` is one run (or one sweep). Values are written as
TOML values (strings, numbers, booleans, lists for swept keys) and passed to the
command's own parser, so its checks and error lines apply unchanged.
"""

import dataclasses
import sys
import tomllib
from collections.abc import Callable
from pathlib import Path

from solar_jax.cli import wants_help
from solar_jax.config import ConfigError
from solar_jax.morphology import MorphologyError
from solar_jax.training.rundir import RunDirError

COMMANDS = ("train", "sweep")
REQUIRED = ("description", "command", "expected", "config")
ALLOWED = (*REQUIRED, "variants")


@dataclasses.dataclass(frozen=True)
class Experiment:
    path: Path
    description: str
    command: str
    expected: str
    variants: tuple[tuple[str, tuple[str, ...]], ...]
    """(variant name, ``key=value`` arguments); one unnamed ("") variant without
    ``[variants]``."""


def is_experiment(argument: str) -> bool:
    return argument.endswith(".toml")


def _argument(key: str, value) -> str:
    if isinstance(value, bool):
        text = str(value).lower()
    elif isinstance(value, list):
        text = "[" + ",".join(str(v) for v in value) + "]"
    else:
        text = str(value)
    return f"{key}={text}"


def _arguments(path: Path, table, where: str) -> tuple[str, ...]:
    if not isinstance(table, dict):
        raise ConfigError(f"{path}: {where} must be a table of key = value")
    nested = [k for k, v in table.items() if isinstance(v, dict)]
    if nested:
        raise ConfigError(
            f"{path}: {where}.{nested[0]} is a table; write dotted keys quoted, "
            f'e.g. "{nested[0]}.<field>" = ...'
        )
    return tuple(_argument(key, value) for key, value in table.items())


def load_experiment(path: str | Path) -> Experiment:
    """An experiment file, read and checked for its shape (its keys are checked by the
    command that runs it); ``ConfigError`` naming the problem otherwise."""
    path = Path(path)
    try:
        data = tomllib.loads(path.read_text())
    except FileNotFoundError:
        raise ConfigError(f"{path}: no such experiment file") from None
    except tomllib.TOMLDecodeError as err:
        raise ConfigError(f"{path}: not valid TOML ({err})") from None
    missing = [k for k in REQUIRED if k not in data]
    unknown = [k for k in data if k not in ALLOWED]
    if missing or unknown:
        what = f"missing {', '.join(missing)}" if missing else f"unknown {', '.join(unknown)}"
        raise ConfigError(f"{path}: {what}; an experiment has {', '.join(ALLOWED)}")
    if data["command"] not in COMMANDS:
        raise ConfigError(f"{path}: command={data['command']}: expected one of train, sweep")
    base = _arguments(path, data["config"], "[config]")
    variants = data.get("variants", {"": {}})
    if not isinstance(variants, dict) or not variants:
        raise ConfigError(f"{path}: [variants] must hold at least one [variants.<name>] table")
    return Experiment(
        path=path,
        description=str(data["description"]),
        command=data["command"],
        expected=str(data["expected"]),
        variants=tuple(
            (name, base + _arguments(path, table, f"[variants.{name}]"))
            for name, table in variants.items()
        ),
    )


def expand(argv: list[str], command: str) -> list[tuple[str, list[str]]]:
    """A command line into the runs it asks for: ``[(variant, arguments)]``. Without an
    experiment file, the line itself; with one (the first argument), each variant's
    arguments, then the line's, with ``out`` per variant when there are several."""
    if not argv or not is_experiment(argv[0]):
        return [("", list(argv))]
    experiment = load_experiment(argv[0])
    if experiment.command != command:
        raise ConfigError(
            f"{argv[0]} is a {experiment.command} experiment: run it with "
            f"python -m solar_jax.{experiment.command} {argv[0]}"
        )
    rest = list(argv[1:])
    if len(experiment.variants) == 1:
        return [(experiment.variants[0][0], [*experiment.variants[0][1], *rest])]
    given_out = next((a.partition("=")[2] for a in rest if a.startswith("out=")), "")
    root = Path(given_out or f"runs/{experiment.path.stem}")
    rest = [a for a in rest if not a.startswith("out=")]
    return [(name, [*args, *rest, f"out={root / name}"]) for name, args in experiment.variants]


def command_main(
    argv: list[str], command: str, usage: Callable[[str | None], str], run: Callable
) -> int:
    """A command's ``main``: ``--help [SECTION]`` prints ``usage(section)``; otherwise
    ``run(arguments)`` for each run the line asks for (``expand``), stopping at the
    first that fails; 2 after a one-line error."""
    try:
        asked, section = wants_help(argv)
        if asked:
            print(usage(section))
            return 0
        runs = expand(argv, command)
    except ConfigError as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    for name, arguments in runs:
        if name:
            print(f"== {argv[0]}: {name}", flush=True)
        code = one_line_errors(run, arguments)
        if code:
            return code
    return 0


def one_line_errors(
    run: Callable[[list[str]], int], arguments: list[str], user_errors: tuple = ()
) -> int:
    """``run(arguments)``'s exit code, its errors as one line on stderr each: 2 for a bad
    input (a setting, a robot, the command's own ``user_errors``), 1 for a fault of the
    files or the disk (a run directory that cannot be written or is damaged, an
    ``OSError``, whose message names the path when the OS gave one)."""
    try:
        return run(arguments)
    except (ConfigError, MorphologyError, *user_errors) as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    except (RunDirError, OSError) as err:
        print(f"error: {err}", file=sys.stderr)
        return 1
