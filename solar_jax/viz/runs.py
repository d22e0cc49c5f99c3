"""Run directories on disk: finding them (sweeps expand into their lanes), reading
them, and grouping seeds into the lines of a plot.

Reads ``config.json`` and ``metrics.jsonl`` as plain JSON (no JAX): plotting a
finished run never builds a trainer.
"""

import dataclasses
from collections.abc import Iterable, Sequence
from pathlib import Path

from solar_jax.morphology import Morphology, MorphologyError, get_suite, load
from solar_jax.training.logger import read_metrics
from solar_jax.training.rundir import (
    BOOKKEEPING,
    CONFIG_FILE,
    METRICS_FILE,
    SWEEP_FILE,
    flatten,
    read_json,
)

NOT_COMPARED = BOOKKEEPING
"""Config keys that never tell two lines apart: seeds are what a line averages over,
the rest is bookkeeping."""

_ALWAYS_NAMED = ("morph", "method")  # the suite is the panel, the method starts the label


class VizError(ValueError):
    """Bad input to a plot (not a run directory, no metrics, no synergies, ...): one line."""


@dataclasses.dataclass(frozen=True, eq=False)
class Run:
    """One run directory, read."""

    path: Path
    config: dict
    """The flattened config (``{"td3.lr": 1e-4, ...}``), lists as tuples."""
    names: tuple[str, ...]
    """The suite's morphologies, training ones first."""
    num_train: int
    records: tuple[dict, ...]

    @property
    def suite(self) -> str:
        return str(self.config["morph"])

    @property
    def method(self) -> str:
        return str(self.config["method"])

    @property
    def held_out(self) -> tuple[str, ...]:
        return self.names[self.num_train :]

    @property
    def has_synergies(self) -> bool:
        return any(f"synergy/{self.names[0]}/labels" in r for r in self.records)

    def morphology(self, name: str) -> Morphology:
        """Robot ``name`` of this run, built as the run built it: by its registered name
        or from its MJCF file (the suite's member; runs name it by the file's stem)."""
        try:
            return load(get_suite(self.suite).members[self.names.index(name)])
        except MorphologyError as err:  # an MJCF file moved since the run
            raise VizError(f"{self.path}: {err}") from None

    def records_of(self, kind: str) -> list[dict]:
        """Records of ``kind`` ("eval" or "round"), in the order logged."""
        return [r for r in self.records if r.get("kind") == kind]


def run_dirs(paths: Sequence[str | Path]) -> list[Path]:
    """Run directories of ``paths``: a run directory as itself, a sweep directory (one
    with ``sweep.json``) as its lanes' run directories, in the sweep's order."""
    if not paths:
        raise VizError("no run directories given")
    found = []
    for given in paths:
        path = Path(given)
        if (path / SWEEP_FILE).is_file():
            lanes = read_json(path / SWEEP_FILE).get("lanes", [])
            if not isinstance(lanes, list) or not all(isinstance(x, dict) for x in lanes):
                raise VizError(f"{path / SWEEP_FILE}: damaged, its lanes are not a list")
            if not lanes:
                raise VizError(f"{path}: {SWEEP_FILE} lists no lanes")
            names = [str(lane.get("run_dir", "")) for lane in lanes]
            if any(Path(name).name != name or name in ("", ".", "..") for name in names):
                raise VizError(f"{path / SWEEP_FILE}: a lane's run_dir is not a folder name")
            found += [path / name for name in names]
        elif (path / CONFIG_FILE).is_file():
            found.append(path)
        elif (path.parent / SWEEP_FILE).is_file():
            raise VizError(f"{path}: a sweep's file, not a run; pass the sweep {path.parent}")
        else:
            raise VizError(
                f"{path}: not a run directory (no {CONFIG_FILE}) nor a sweep directory "
                f"(no {SWEEP_FILE})"
            )
    return found


def load_run(path: str | Path) -> Run:
    """A run directory's config and metrics."""
    path = Path(path)
    if not (path / CONFIG_FILE).is_file():
        raise VizError(f"{path}: not a run directory (no {CONFIG_FILE})")
    saved = read_json(path / CONFIG_FILE)
    if not (path / METRICS_FILE).is_file():
        raise VizError(f"{path}: no {METRICS_FILE} (the run has not logged anything)")
    records = read_metrics(path)
    if not records:
        raise VizError(f"{path}: {METRICS_FILE} is empty (the run has not logged anything)")
    try:
        resolved = saved["resolved"]
        return Run(
            path=path,
            config=flatten(saved["config"]),
            names=tuple(resolved["morphologies"]),
            num_train=int(resolved["num_train"]),
            records=tuple(records),
        )
    except (KeyError, TypeError, ValueError, AttributeError) as err:
        raise VizError(f"{path / CONFIG_FILE}: damaged ({type(err).__name__}: {err})") from None


def load_runs(paths: Sequence[str | Path]) -> list[Run]:
    """Every run of ``paths`` (run or sweep directories), read."""
    return [load_run(path) for path in run_dirs(paths)]


def suite_name(suite: str) -> str:
    """A suite as a title: an MJCF path by its file name."""
    return Path(suite).stem if suite.lower().endswith(".xml") else suite


def _format(value) -> str:
    return f"{value:g}" if isinstance(value, float) else str(value)


def varying_keys(runs: Iterable[Run]) -> list[str]:
    """Config keys whose values differ among ``runs``, besides ``NOT_COMPARED``, the
    suite and the method; where the schedule differs, not the keys that it alone sets
    (one value per schedule: ``schedule=fast``, not its eight keys)."""
    runs = list(runs)
    keys = sorted({key for run in runs for key in run.config})
    skip = NOT_COMPARED | set(_ALWAYS_NAMED)

    def values(key: str, among: list[Run]) -> set[str]:
        return {repr(run.config.get(key)) for run in among}

    varying = [key for key in keys if key not in skip and len(values(key, runs)) > 1]
    if "schedule" not in varying:
        return varying
    by_schedule: dict[str, list[Run]] = {}
    for run in runs:
        by_schedule.setdefault(str(run.config.get("schedule", "paper")), []).append(run)
    return [
        key
        for key in varying
        if key == "schedule" or any(len(values(key, group)) > 1 for group in by_schedule.values())
    ]


def group_runs(runs: Sequence[Run]) -> dict[tuple[str, str], list[Run]]:
    """Runs grouped into lines: ``{(suite, label): runs}``, where the label is the
    method plus ``key=value`` for every config key that varies among the suite's runs
    (``solar td3.lr=0.0003``). Groups keep the order in which they first appear."""
    groups: dict[tuple[str, str], list[Run]] = {}
    for suite in dict.fromkeys(run.suite for run in runs):
        members = [run for run in runs if run.suite == suite]
        keys = varying_keys(members)
        for run in members:
            label = " ".join([run.method, *(f"{k}={_format(run.config.get(k))}" for k in keys)])
            groups.setdefault((suite, label), []).append(run)
    return groups


def run_names(runs: Sequence[Run]) -> list[str]:
    """Short unique names: the directory's name, with its parent's where that repeats
    (the lanes of two sweeps are both ``seed0``)."""
    paths = [run.path.resolve() for run in runs]
    names = [path.name for path in paths]
    return [
        f"{path.parent.name}-{name}" if names.count(name) > 1 else name
        for path, name in zip(paths, names, strict=True)
    ]
