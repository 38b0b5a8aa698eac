"""The one atomic writer: a file appears under its final name only when it is complete.

Why: an interrupted write must never destroy what was there before (a checkpoint, a model, a
figure, a recording), and a reader must never see half a file under the final name. Every
output of depthseg (MCAP recordings, checkpoints, ONNX models, figures, JSON) goes through
`atomic_write`; the MCAP writers use `atomic_path` for their long-lived temporary file.
"""

from __future__ import annotations

import json
import os
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

from edge.errors import DataError

__all__ = ["atomic_path", "atomic_write", "write_bytes_atomic", "write_json_atomic"]


def atomic_path(path: str | Path) -> Path:
    """Temporary sibling of ``path`` (hidden, per process): write there, then ``os.replace`` it."""
    path = Path(path)
    return path.with_name(f".{path.name}.{os.getpid()}.tmp")


@contextmanager
def atomic_write(path: str | Path, fsync: bool = False) -> Iterator[Path]:
    """Yield a temporary path to write; it replaces ``path`` only if the block succeeds.

    Args:
        path: the final file name.
        fsync: flush the temporary file to disk before the rename (for files a crash must not
            leave empty, such as recordings).

    Yields:
        The temporary path; the caller writes the whole file there.
    """
    path = Path(path)
    if path.exists() and not path.is_file():
        raise DataError(f"{path} exists and is not a regular file (a directory, FIFO or device); give a new file name")
    tmp = atomic_path(path)
    try:
        yield tmp
        if fsync and tmp.exists():
            with open(tmp, "rb+") as fh:
                os.fsync(fh.fileno())
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)


def write_bytes_atomic(path: str | Path, data: bytes) -> Path:
    """Write ``data`` to ``path`` atomically; returns ``path``."""
    with atomic_write(path) as tmp:
        tmp.write_bytes(data)
    return Path(path)


def write_json_atomic(path: str | Path, obj: Any, indent: int | None = 2) -> Path:
    """Write ``obj`` as JSON (keys sorted, trailing newline) to ``path`` atomically."""
    return write_bytes_atomic(path, (json.dumps(obj, indent=indent, sort_keys=True) + "\n").encode())
