"""Files written so that no reader ever sees half of one: the run directories' JSON,
the metrics a resume rewrites, and the compilation cache's programs and times."""

import os
import threading
from pathlib import Path


def write_atomic(path: Path, data: str | bytes) -> None:
    """``path`` holds ``data`` whole or is left as it was: written beside it under a name
    of this process and thread (concurrent writers never share one; one rename wins),
    then renamed over it; an ``OSError`` removes the partial file and propagates."""
    tmp = path.with_name(f".{path.name}.{os.getpid()}-{threading.get_ident()}.tmp")
    try:
        tmp.write_bytes(data.encode() if isinstance(data, str) else data)
        tmp.replace(path)
    except OSError:
        tmp.unlink(missing_ok=True)
        raise
