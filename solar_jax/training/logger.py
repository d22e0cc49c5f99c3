"""Host-side metric sinks: JSON lines, optional TensorBoard, and a progress bar."""

import json
import math
import sys
import time
from pathlib import Path

from solar_jax.training.rundir import METRICS_FILE


class MetricsLog:
    """Appends flat metric dicts to ``metrics.jsonl`` (and TensorBoard when asked).

    On resume, lines of rounds after the restored checkpoint are dropped, so the file
    reads as if the run had never stopped.
    """

    def __init__(self, run_dir: Path, tensorboard: bool = False, keep_rounds: int | None = None):
        self.path = Path(run_dir) / METRICS_FILE
        if keep_rounds is not None and self.path.exists():
            lines = self.path.read_text().splitlines()
            kept = [line for line in lines if json.loads(line)["round"] <= keep_rounds]
            self.path.write_text("".join(f"{line}\n" for line in kept))
        self.file = self.path.open("a")
        self.writer = None
        if tensorboard:
            try:
                from tensorboardX import SummaryWriter
            except ImportError:
                raise RuntimeError(
                    "tensorboard=true needs the tensorboardX package (pip install tensorboardX)"
                ) from None
            self.writer = SummaryWriter(str(Path(run_dir) / "tensorboard"))

    def write(self, record: dict) -> None:
        self.file.write(json.dumps(record) + "\n")
        self.file.flush()
        if self.writer is not None:
            for key, value in record.items():
                if isinstance(value, int | float) and not isinstance(value, bool):
                    self.writer.add_scalar(key, value, record["env_steps"])

    def close(self) -> None:
        self.file.close()
        if self.writer is not None:
            self.writer.close()


def read_metrics(run_dir: str | Path) -> list[dict]:
    """The records of a run's ``metrics.jsonl``."""
    with (Path(run_dir) / METRICS_FILE).open() as f:
        return [json.loads(line) for line in f if line.strip()]


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
