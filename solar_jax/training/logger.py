"""Host-side metric sinks: JSON lines, optional TensorBoard, and a progress bar."""

import json
import math
import sys
import time
from pathlib import Path

from solar_jax.config import ConfigError
from solar_jax.files import write_atomic
from solar_jax.training.rundir import METRICS_FILE, RunDirError, cause


class MetricsLog:
    """Appends flat metric dicts to ``metrics.jsonl`` (and TensorBoard when asked), each
    record one ``write`` of one line.

    On resume, lines of rounds after the restored checkpoint are dropped (``keep_rounds``;
    -1: all, a run started over), and a torn last line (a write cut short by a full
    disk or a kill) with them, so the file reads as if the run had never stopped.
    """

    def __init__(self, run_dir: Path, tensorboard: bool = False, keep_rounds: int | None = None):
        self.path = Path(run_dir) / METRICS_FILE
        try:
            if keep_rounds is not None and self.path.exists():
                kept = [r for r in read_metrics(run_dir) if r["round"] <= keep_rounds]
                write_atomic(self.path, "".join(json.dumps(r) + "\n" for r in kept))
            self.file = self.path.open("a")
        except OSError as err:
            raise RunDirError(f"{self.path}: cannot be written ({cause(err)})") from None
        self.writer = None
        if tensorboard:
            try:
                from tensorboardX import SummaryWriter
            except ImportError:
                raise ConfigError(
                    'tensorboard=true needs tensorboardX: pip install -e ".[tensorboard]"'
                ) from None
            self.writer = SummaryWriter(str(Path(run_dir) / "tensorboard"))

    def write(self, record: dict) -> None:
        try:
            self.file.write(json.dumps(record) + "\n")
            self.file.flush()
        except OSError as err:
            raise RunDirError(f"{self.path}: cannot be written ({cause(err)})") from None
        if self.writer is not None:
            for key, value in record.items():
                if isinstance(value, int | float) and not isinstance(value, bool):
                    self.writer.add_scalar(key, value, record["env_steps"])

    def close(self) -> None:
        try:
            self.file.close()
        except OSError:
            pass  # its last write failed already, and said so
        if self.writer is not None:
            self.writer.close()


class MetricsError(RunDirError):
    """A ``metrics.jsonl`` damaged before its last line (which a cut write may tear)."""


def read_metrics(run_dir: str | Path) -> list[dict]:
    """The records of a run's ``metrics.jsonl``. A torn last line (a write cut short) is
    skipped with a warning on stderr; a damaged line before it is a ``MetricsError``."""
    path = Path(run_dir) / METRICS_FILE
    lines = path.read_bytes().split(b"\n")
    records = []
    for number, line in enumerate(lines, 1):
        if not line.strip():
            continue
        try:
            record = json.loads(line)
            if not isinstance(record, dict) or "round" not in record:
                raise ValueError("not a record")
        except ValueError:
            if number == len(lines):  # no newline after it: the write was cut short
                print(
                    f"warning: {path}: its last line is torn (a cut write); skipped",
                    file=sys.stderr,
                )
                continue
            raise MetricsError(f"{path}: line {number} is damaged (not a metrics record)") from None
        records.append(record)
    return records


def duration(seconds: float) -> str:
    """``seconds`` as the largest sensible unit: 42 s, 3.5 min, 7.1 h, 12.3 days."""
    for unit, size in (("days", 86400), ("h", 3600), ("min", 60)):
        if seconds >= 2 * size:
            return f"{seconds / size:.1f} {unit}"
    return f"{seconds:.0f} s"


class ProgressBar:
    """One status line on stderr: redrawn in place on a terminal, else every ``every_s``;
    the ETA extrapolates the rate since the first update."""

    def __init__(self, total: int, enabled: bool = True, every_s: float = 30.0):
        self.total, self.enabled, self.every_s = total, enabled, every_s
        self.tty = sys.stderr.isatty()
        self.last = -math.inf
        self.first = None  # (time, steps) of the first update

    def eta(self, now: float, done: int) -> str:
        if self.first is None:
            self.first = (now, done)
        start, start_done = self.first
        if done <= start_done or done >= self.total:
            return "-"
        return duration((now - start) * (self.total - done) / (done - start_done))

    def update(self, done: int, **fields: float) -> None:
        now = time.monotonic()
        eta = self.eta(now, done)
        if not self.enabled or (not self.tty and now - self.last < self.every_s):
            return
        self.last = now
        frac = min(done / self.total, 1.0)
        bar = "#" * int(24 * frac) + "." * (24 - int(24 * frac))
        info = " | ".join(f"{k} {v:,.1f}" for k, v in fields.items())
        line = f"[{bar}] {100 * frac:5.1f}% {done:,}/{self.total:,} steps | eta {eta} | {info}"
        print(("\r" if self.tty else "") + line, end="" if self.tty else "\n", file=sys.stderr)
        sys.stderr.flush()

    def close(self) -> None:
        if self.enabled and self.tty:
            print(file=sys.stderr)
