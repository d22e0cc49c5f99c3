"""What every benchmark part shares: its command line (``train``'s keys and the part's
own options on one grammar), the machine and versions it ran on, its table and JSON."""

import dataclasses
import json
import os
import platform
import subprocess
import time
from collections.abc import Callable, Sequence
from importlib import metadata
from pathlib import Path

import jax

from solar_jax.cli import (
    apply_overrides,
    help_text,
    option_entries,
    parse_config,
    split_arguments,
    unknown_key,
    valid_keys,
    wants_help,
)
from solar_jax.config import ConfigError, TrainConfig
from solar_jax.experiments import one_line_errors

PACKAGES = ("jax", "jaxlib", "mujoco", "mujoco-mjx", "flax", "optax", "numpy", "solar_jax")


@dataclasses.dataclass(frozen=True)
class Part:
    """One benchmark: ``run(config, options, config_argv) -> {"rows": [...], ...}``,
    ``table(result) -> str`` (markdown), its options (a dataclass's defaults) and
    docstring; ``status(result)``: the exit status of a result (default 0)."""

    name: str
    doc: str
    options: object
    run: Callable
    table: Callable
    status: Callable = lambda result: 0


def parse(argv: Sequence[str], options) -> tuple[TrainConfig, object, list[str]]:
    """(``train``'s config, the part's options, the ``train`` arguments as given) of a
    command line: keys of ``options`` go to it, the rest to ``parse_config``."""
    overrides = split_arguments(TrainConfig, argv)
    own_keys = valid_keys(type(options))
    own = {k: v for k, v in overrides.items() if k in own_keys}
    rest = [f"{k}={v}" for k, v in overrides.items() if k not in own_keys]
    try:
        config = parse_config(rest)
    except ConfigError as err:
        unknown = [k for k in overrides if k not in own_keys and k not in valid_keys(TrainConfig)]
        if unknown:  # the closest of both the part's keys and train's
            raise ConfigError(
                unknown_key(unknown[0], [*own_keys, *valid_keys(TrainConfig)])
            ) from None
        raise err from None
    return config, apply_overrides(options, own), rest


def machine() -> dict:
    """The device, the host and the versions a measurement ran with."""
    device = jax.devices()[0]
    versions = {}
    for package in PACKAGES:
        try:
            versions[package] = metadata.version(package)
        except metadata.PackageNotFoundError:
            versions[package] = None
    return {
        "device": device.device_kind,
        "platform": device.platform,
        "devices": jax.device_count(),
        "host": platform.processor() or platform.machine(),
        "cpus": os.cpu_count(),
        "python": platform.python_version(),
        "versions": versions,
        "commit": commit(Path(__file__).resolve().parents[2]),
    }


def describe(meta: dict) -> str:
    """One line: device, host and versions."""
    versions = ", ".join(f"{k} {v}" for k, v in meta["versions"].items() if v)
    return (
        f"device: {meta['device']} ({meta['platform']}, {meta['devices']} device(s)); "
        f"host: {meta['cpus']} CPUs; {versions}"
    )


def commit(repo: Path) -> str | None:
    """The repository's short commit, None outside a git checkout."""
    try:
        return subprocess.run(
            ["git", "-C", str(repo), "rev-parse", "--short", "HEAD"],
            capture_output=True,
            text=True,
            check=True,
        ).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return None


def markdown(columns: dict[str, str], rows: Sequence[dict]) -> str:
    """A markdown table: ``columns`` maps each header to a format string of a row."""
    lines = ["| " + " | ".join(columns) + " |", "|---" + "|---:" * (len(columns) - 1) + "|"]
    lines += ["| " + " | ".join(f.format(**r) for f in columns.values()) + " |" for r in rows]
    return "\n".join(lines)


def options_dict(options) -> dict:
    return {k: list(v) if isinstance(v, tuple) else v for k, v in vars(options).items()}


def write(path: Path, meta: dict, result: dict) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps({"meta": meta, **result}, indent=1, default=str))
    return path


def output_path(out: str, name: str, meta: dict, results: Path | None) -> Path:
    """``out`` if given, else ``<name>_<device>.json`` in ``results`` (the current folder
    when None)."""
    if out:
        return Path(out)
    return (results or Path()) / f"bench_{name}_{meta['device'].replace(' ', '_')}.json"


def main(part: Part, argv: Sequence[str], results: Path | None = None) -> int:
    """A part's command: ``--help [SECTION]``, else parse, measure, print the table, write
    the JSON (``out=PATH``, or ``bench_<part>_<device>.json``); 2 after a one-line error."""
    asked, section = wants_help(argv)
    if asked:
        print(help_text(TrainConfig(), part.doc, section, option_entries(part.options)))
        return 0

    def measure(argv) -> int:
        config, options, config_argv = parse(argv, part.options)
        meta = machine()
        print(describe(meta), flush=True)
        start = time.perf_counter()
        result = part.run(config, options, config_argv)
        meta |= {
            "part": part.name,
            "argv": list(argv),
            "options": options_dict(options),
            "seconds": time.perf_counter() - start,
        }
        print(part.table(result))
        path = write(output_path(options.out, part.name, meta, results), meta, result)
        print(f"-> {path}")
        return part.status(result)

    return one_line_errors(measure, list(argv))
