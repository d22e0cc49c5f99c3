"""What run and sweep directories hold, without JAX (``solar_jax.viz`` reads them too):
the one place their format is written down.

A run directory (default ``runs/<morph>-<method>-seed<seed>-<time>``): ``config.json``
(the config and what it resolved to), ``metrics.jsonl``, ``checkpoints/`` (the latest
ones, and in ``best/`` the policy at the best evaluation). A sweep directory
(``runs/<morph>-<method>-sweep-<time>``): ``sweep.json``, ``aggregate.json`` and one run
directory per lane.
"""

import json
import os
import socket
import time
from pathlib import Path

from solar_jax.config import ConfigError, TrainConfig, config_from_dict, config_to_dict
from solar_jax.files import write_atomic

CONFIG_FILE = "config.json"
METRICS_FILE = "metrics.jsonl"
CHECKPOINTS = "checkpoints"
LOCK_FILE = "run.lock"
BEST = "best"
"""In ``checkpoints/``: the policy at the best evaluation (``Runner.save_best``)."""
RUN_FILES = (CONFIG_FILE, METRICS_FILE, CHECKPOINTS)
"""What a run writes in its directory: a fresh run refuses a directory holding any."""
SWEEP_FILE = "sweep.json"
AGGREGATE_FILE = "aggregate.json"

RESUMABLE = (
    "total_steps",
    "eval_every",
    "eval_episodes",
    "checkpoint_every",
    "keep_checkpoints",
    "time_limit",
    "tensorboard",
    "progress",
    "plots",
)
"""Keys that may differ from the saved config when resuming; the rest must not."""

BOOKKEEPING = frozenset({"seed", "out", "resume", "dry_run", *RESUMABLE})
"""Top-level config keys that change neither the compiled programs nor what a line of
a plot compares: seeds are what a line averages over, the rest is bookkeeping. Traced
code must not read them: programs kept on disk are keyed without them
(``Trainer.fingerprint``)."""


def config_record(config: TrainConfig, resolved: dict) -> dict:
    """``config.json``: the config as given, and what it resolved to (``resolved``: the
    checkpoint format, the morphologies, the training count, N_max, the replay's full
    capacity)."""
    keys = {"format_version", "morphologies", "num_train", "n_max", "replay_capacity"}
    if set(resolved) != keys:
        raise ValueError(f"config.json's resolved part has {sorted(resolved)}, not {sorted(keys)}")
    return {"config": config_to_dict(config), "resolved": resolved}


def check_resumable(directory: str, overrides: dict[str, str], what: str) -> None:
    """One error line naming the ``overrides`` a resume of saved ``what`` (a run, a
    sweep) may not change."""
    fixed = sorted(k for k in overrides if k.split(".")[0] not in RESUMABLE)
    if fixed:
        raise ConfigError(
            f"resume={directory}: cannot change {', '.join(fixed)} of a saved {what}; "
            f"only {', '.join(RESUMABLE)} may be given"
        )


def default_run_dir(config: TrainConfig, sweep: bool = False) -> Path:
    """Where a run (or a sweep) without ``out`` writes: named by its suite, method and
    seed, and the time it started."""
    morph = Path(config.morph).stem if config.morph.endswith(".xml") else config.morph
    stamp = time.strftime("%Y%m%d-%H%M%S")
    what = "sweep" if sweep else f"seed{config.seed}"
    return Path("runs") / f"{morph}-{config.method}-{what}-{stamp}"


class RunDirError(RuntimeError):
    """A run or sweep directory that cannot be used: unwritable, damaged, or in use by
    another process. The message names the path and the cause."""


def cause(err: OSError) -> str:
    """An ``OSError`` in words, without the path (the caller names it)."""
    return err.strerror or str(err)


def checkpoint_steps(run_dir: str | Path) -> list[int]:
    """The steps of a run directory's complete checkpoints, oldest first (orbax writes
    each under a temporary name and renames it to its step when complete)."""
    checkpoints = Path(run_dir) / CHECKPOINTS
    if not checkpoints.is_dir():
        return []
    return sorted(int(p.name) for p in checkpoints.iterdir() if p.is_dir() and p.name.isdigit())


def has_checkpoint(run_dir: str | Path) -> bool:
    """Whether a run directory holds a complete checkpoint to resume from."""
    return bool(checkpoint_steps(run_dir))


def read_json(path: Path, what: str = "") -> dict:
    """A JSON object from ``path``; damaged or unreadable: ``ConfigError`` naming it."""
    try:
        data = json.loads(path.read_text())
    except OSError as err:
        raise ConfigError(f"{what}{path}: cannot be read ({cause(err)})") from None
    except ValueError as err:  # JSONDecodeError, or bytes that are not text
        raise ConfigError(f"{what}{path}: damaged, not JSON ({err})") from None
    if not isinstance(data, dict):
        raise ConfigError(f"{what}{path}: damaged, not a JSON object")
    return data


ADDED = {"env.layout": "per_robot"}
"""Keys added since some runs began, with the value such runs ran with where it is not
today's default: they resume as they ran."""
REMOVED = {"env.robots_per_world": 1}
"""Keys removed since some runs began, with the one value the code still runs: a run
saved with another cannot resume."""


def migrated(config: dict, where: str) -> dict:
    """A saved config's dict in today's keys (``ADDED``, ``REMOVED``); ``where`` names
    it in the error of a run that cannot resume."""
    flat = flatten(config)
    for key, value in REMOVED.items():
        if key in flat and flat.pop(key) != value:
            raise ConfigError(
                f"{where}: {key}={flatten(config)[key]} is no longer built (merged worlds); "
                f"this version resumes only runs with {key}={value}"
            )
    for key, value in ADDED.items():
        flat.setdefault(key, value)
    out: dict = {}
    for key, value in flat.items():
        *sections, name = key.split(".")
        node = out
        for section in sections:
            node = node.setdefault(section, {})
        node[name] = list(value) if isinstance(value, tuple) else value
    return out


def saved_config(run_dir: str | Path) -> TrainConfig:
    """The config a run directory was started with; a damaged one is a ``ConfigError``
    naming the file and what is wrong."""
    path = Path(run_dir) / CONFIG_FILE
    if not path.is_file():
        raise ConfigError(f"resume={run_dir}: no {CONFIG_FILE} there (not a run directory)")
    saved = read_json(path)
    if "config" not in saved:
        raise ConfigError(f"{path}: damaged, no 'config' section")
    try:
        return config_from_dict(TrainConfig, migrated(saved["config"], str(path)))
    except ValueError as err:
        raise ConfigError(f"{path}: {err}") from None


def flatten(tree: dict, prefix: str = "") -> dict:
    """``{"td3": {"lr": 1}}`` -> ``{"td3.lr": 1}``; lists become tuples (hashable, and a
    config's tuples compare equal to their JSON copies)."""
    flat = {}
    for key, value in tree.items():
        if isinstance(value, dict):
            flat |= flatten(value, f"{prefix}{key}.")
        else:
            flat[prefix + key] = tuple(value) if isinstance(value, list) else value
    return flat


def check_same_run(run_dir: str | Path, config: TrainConfig, saved: dict) -> None:
    """A ``ConfigError`` when ``config`` (``config.json`` with the command line's
    ``RESUMABLE`` keys) differs from a checkpoint's own copy ``saved`` in a key the
    command line could not change: the file was edited, and the run would not continue
    as it was."""
    free = {*RESUMABLE, "out", "resume", "dry_run"}
    given = flatten(config_to_dict(config))
    kept = flatten(migrated(saved, f"{run_dir}'s checkpoint"))
    default = flatten(config_to_dict(TrainConfig()))

    def differs(key: str) -> bool:
        if key not in kept:  # a key added since the run began: it ran with its default
            return given[key] != default.get(key)
        return given.get(key) != kept[key]

    changed = sorted(
        k for k in given.keys() | kept.keys() if k.split(".")[0] not in free and differs(k)
    )
    if changed:
        shown = ", ".join(f"{k} {given.get(k)!r} (checkpoint: {kept.get(k)!r})" for k in changed)
        raise ConfigError(
            f"{Path(run_dir) / CONFIG_FILE} differs from its checkpoint's config in {shown}; "
            f"only {', '.join(RESUMABLE)} may change on resume"
        )


def make_run_dir(run_dir: Path) -> None:
    """Creates a run (or sweep) directory, or a ``RunDirError`` naming it and the cause."""
    if run_dir.exists() and not run_dir.is_dir():
        raise RunDirError(f"out={run_dir}: a file of that name is in the way")
    try:
        run_dir.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        raise RunDirError(f"out={run_dir}: cannot be created ({cause(err)})") from None


def write_file(path: Path, text: str) -> None:
    """``write_atomic``, an ``OSError`` as a ``RunDirError`` naming ``path``."""
    try:
        write_atomic(path, text)
    except OSError as err:
        raise RunDirError(f"{path}: cannot be written ({cause(err)})") from None


class RunLock:
    """``with RunLock(directory):`` this process alone writes in ``directory``: a lock
    file holding the owner's pid and host, created exclusively. A lock whose owner on this
    host is gone (a crash, a kill) is stale: it is taken over and said so. Anyone else's
    is a ``RunDirError`` naming the owner and the file."""

    def __init__(self, directory: str | Path):
        self.path = Path(directory) / LOCK_FILE
        self.owner = {"pid": os.getpid(), "host": socket.gethostname()}

    def _holder(self) -> dict | None:
        """The lock's owner, or None when it is stale (gone from this host, or a file
        left unwritten by a process that died creating it)."""
        try:
            holder = json.loads(self.path.read_text())
            pid, host = int(holder["pid"]), str(holder["host"])
        except FileNotFoundError:
            return None
        except (OSError, ValueError, KeyError, TypeError):
            young = time.time() - self.path.stat().st_mtime < 10  # its owner may be writing
            return {"pid": "?", "host": "?"} if young else None
        if host != self.owner["host"]:
            return holder  # another host's process: cannot be checked from here
        try:
            os.kill(pid, 0)
        except ProcessLookupError:
            return None
        except PermissionError:  # alive, another user's
            pass
        return holder

    def acquire(self) -> None:
        for _ in range(2):
            try:
                fd = os.open(self.path, os.O_CREAT | os.O_EXCL | os.O_WRONLY, 0o644)
            except FileExistsError:
                holder = self._holder()
                if holder is not None:
                    raise RunDirError(
                        f"{self.path.parent} is in use by process {holder['pid']} on "
                        f"{holder['host']} (lock {self.path}); if that process is gone, "
                        "delete the lock file"
                    ) from None
                print(f"note: {self.path}: its process is gone; taking the lock over")
                self.path.unlink(missing_ok=True)
                continue
            except OSError as err:
                raise RunDirError(
                    f"{self.path.parent}: cannot write there ({cause(err)})"
                ) from None
            try:
                with os.fdopen(fd, "w") as f:
                    f.write(json.dumps(self.owner))
            except OSError as err:
                self.path.unlink(missing_ok=True)
                raise RunDirError(f"{self.path}: cannot be written ({cause(err)})") from None
            return
        raise RunDirError(f"{self.path}: another process took the lock at the same time")

    def release(self) -> None:
        try:
            if json.loads(self.path.read_text()) == self.owner:
                self.path.unlink()
        except (OSError, ValueError):
            pass  # not ours any more, or gone

    def __enter__(self) -> "RunLock":
        self.acquire()
        return self

    def __exit__(self, *exc) -> None:
        self.release()
