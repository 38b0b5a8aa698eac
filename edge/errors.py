"""Exception hierarchy shared by every depthseg package.

Library code raises these; the CLIs catch `DepthsegError` and print its message as one line
with a non-zero exit code, so a user sees what went wrong and how to fix it, never a traceback.
Messages name the offending value and the valid options or the fix.
"""

from __future__ import annotations

__all__ = [
    "DepthsegError",
    "ConfigError",
    "DataError",
    "McapDataError",
    "ModelError",
    "ThresholdError",
    "MissingExtraError",
    "first_line",
]


class DepthsegError(Exception):
    """Base class: anything a user can cause and fix."""


class ConfigError(DepthsegError, ValueError):
    """A bad argument or option value (unknown name, min above max, zero frames...)."""


class DataError(DepthsegError):
    """Input data that cannot be used (missing file, wrong shape, no labels...)."""


class McapDataError(DataError):
    """An MCAP file that cannot be read as depth frames (corrupt, wrong encoding, no topic)."""


class ModelError(DepthsegError):
    """A model file that is missing, corrupt or inconsistent with its metadata."""


class ThresholdError(DepthsegError):
    """No decision boundary satisfies the requested objective."""


class MissingExtraError(DepthsegError):
    """A module of an optional extra (``pip install 'depthseg[train]'``...) that this command needs is missing."""


def first_line(exc: BaseException, limit: int | None = None) -> str:
    """The first line of an exception's message for a one-line error (its class name when empty).

    Why one helper: library errors (onnx, Ray, numpy) quote whole tracebacks or reports; a
    depthseg message quotes their first line only, and an empty message must not fail the quoting.

    Args:
        exc: the exception to quote.
        limit: cut the line to at most this many characters (None: whole).
    """
    text = str(exc).strip()
    line = text.splitlines()[0] if text else type(exc).__name__
    return line if limit is None else line[:limit]
