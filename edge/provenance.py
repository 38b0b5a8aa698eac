"""Which depthseg made a file: package version and, in a git checkout, the commit.

Why: a model, checkpoint or simulated data set found on a robot months later must say what
produced it. ``provenance()`` is stored in ONNX ``metadata_props``, checkpoints and the simulator
manifest; ``--version`` of every command prints the same. The commit is read at run time with
``git`` when the package sits in a git checkout (an editable install); an installed wheel, or a
machine without git, says ``"unknown"``.
"""

from __future__ import annotations

import functools
import subprocess
from pathlib import Path

__all__ = ["package_version", "git_commit", "provenance", "version_string"]

_ROOT = Path(__file__).resolve().parents[1]


@functools.lru_cache(maxsize=1)
def package_version() -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("depthseg")
    except PackageNotFoundError:
        return "unknown"


@functools.lru_cache(maxsize=1)
def git_commit() -> str:
    """Full hash of HEAD (with ``-dirty`` when tracked files changed), or ``"unknown"``."""
    if not (_ROOT / ".git").exists():
        return "unknown"
    try:
        head = subprocess.run(
            ["git", "-C", str(_ROOT), "rev-parse", "HEAD"], capture_output=True, text=True, timeout=5, check=True
        ).stdout.strip()
        dirty = subprocess.run(
            ["git", "-C", str(_ROOT), "status", "--porcelain", "--untracked-files=no"],
            capture_output=True, text=True, timeout=5, check=True,
        ).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        return "unknown"
    if len(head) != 40:
        return "unknown"
    return head + ("-dirty" if dirty else "")


def provenance() -> dict[str, str]:
    """``{"depthseg_version": ..., "git_commit": ...}``."""
    return {"depthseg_version": package_version(), "git_commit": git_commit()}


def version_string(prog: str) -> str:
    c = git_commit()
    return f"{prog} (depthseg) {package_version()}" + ("" if c == "unknown" else f" (git {c[:12]}{'-dirty' if c.endswith('-dirty') else ''})")
