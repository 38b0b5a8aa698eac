"""Shared plumbing for the thin ``main(argv) -> int`` CLIs.

Every console script wraps its body in `run`, so a `DepthsegError` (or a missing file, or an
unwritable output) becomes one line on stderr and exit code 2, never a traceback.
"""

from __future__ import annotations

import json
import sys
from collections.abc import Callable
from typing import Any

from edge.errors import DepthsegError

__all__ = ["run", "fail", "print_json", "progress"]


def fail(prog: str, message: str, code: int = 2) -> int:
    print(f"{prog}: error: {message}", file=sys.stderr)
    return code


def run(prog: str, body: Callable[[], int | None]) -> int:
    """Call ``body``; map user-fixable errors to a one-line message and a non-zero code."""
    try:
        rc = body()
        return 0 if rc is None else int(rc)
    except DepthsegError as exc:
        return fail(prog, str(exc))
    except FileNotFoundError as exc:
        return fail(prog, f"{exc.filename}: no such file or directory")
    except IsADirectoryError as exc:
        return fail(prog, f"{exc.filename}: is a directory, expected a file")
    except PermissionError as exc:
        return fail(prog, f"{exc.filename}: permission denied; choose a writable path")
    except KeyboardInterrupt:
        print(f"{prog}: interrupted", file=sys.stderr)
        return 130


def print_json(obj: Any) -> None:
    """One JSON object on stdout, for scripts (numpy scalars converted)."""

    def default(o: Any) -> Any:
        try:
            import numpy as np

            if isinstance(o, np.generic):
                return o.item()
            if isinstance(o, np.ndarray):
                return o.tolist()
        except ImportError:  # pragma: no cover
            pass
        return str(o)

    print(json.dumps(obj, default=default, sort_keys=True))


def progress(iterable=None, total: int | None = None, desc: str = "", disable: bool | None = None, **kw):
    """A tqdm bar on a terminal (stderr), silent when stderr is not a TTY unless forced."""
    from tqdm import tqdm

    if disable is None:
        disable = not sys.stderr.isatty()
    return tqdm(iterable, total=total, desc=desc, disable=disable, dynamic_ncols=True, **kw)
