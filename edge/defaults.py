"""Where the shipped default model lives, and the one rule that picks a model file.

Every command uses the shipped model when ``--model`` is omitted: `resolve_model` decides which
file that is (ONNX for the edge path, the checkpoint for torch tools, whichever exists for
tools that take both) and gives the one error a user sees when it is missing.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path

from edge.errors import ModelError

__all__ = ["MODELS_DIR", "DEFAULT_CHECKPOINT", "DEFAULT_ONNX", "FAST_CHECKPOINT", "FAST_ONNX", "SUFFIXES",
           "default_model", "resolve_model", "default_models", "is_shipped_model", "user_models_dir"]

MODELS_DIR = Path(__file__).resolve().parent / "models"
DEFAULT_CHECKPOINT = MODELS_DIR / "default.pt"  # torch checkpoint, 3-channel (paper input)
DEFAULT_ONNX = MODELS_DIR / "default.onnx"  # single-channel fp32 export of the same weights
# The fast option (candidate N6, README "The fast option"): the default's recipe at width x0.0625,
# x0.67-0.69 of its whole-frame latency, 0.56 IoU points lower on held-out simulated frames. Never
# picked implicitly: a user names it with --model.
FAST_CHECKPOINT = MODELS_DIR / "fast.pt"
FAST_ONNX = MODELS_DIR / "fast.onnx"
SUFFIXES = {"onnx": (".onnx",), "pt": (".pt", ".pth")}
_REBUILD = {
    "onnx": "export it: depthseg-export --single-channel --out edge/models/default.onnx",
    "pt": "rebuild it: bash tools/train_default.sh",
}


def _default(kind: str) -> Path:
    # looked up at call time so tests can point the defaults elsewhere
    return DEFAULT_ONNX if kind == "onnx" else DEFAULT_CHECKPOINT


def default_models(kinds: Sequence[str] = ("onnx", "pt")) -> list[Path]:
    """The shipped model files of ``kinds`` that exist, in the order of ``kinds``."""
    return [_default(k) for k in kinds if _default(k).exists()]


def resolve_model(path: str | Path | None, kinds: Sequence[str] = ("onnx", "pt")) -> Path:
    """The model file to use: ``path`` checked, or the first shipped default of ``kinds`` that exists.

    Args:
        path: a model file, or None for the shipped default.
        kinds: acceptable kinds, ``"onnx"`` and/or ``"pt"``, in order of preference.

    Returns:
        An existing file.

    Raises:
        ModelError: the file (or every default of ``kinds``) is missing, or ``path`` is a directory.
    """
    if path is None:
        found = default_models(kinds)
        if found:
            return found[0]
        missing = " or ".join(str(_default(k)) for k in kinds)
        raise ModelError(
            f"the shipped default model is missing ({missing}); name a model file, reinstall depthseg "
            f"(pip install --force-reinstall depthseg), or in a source checkout {_REBUILD[kinds[0]]}"
        )
    p = Path(path)
    if not p.exists():
        raise ModelError(f"{p}: no such model file")
    if p.is_dir():
        want = " or ".join(s for k in kinds for s in SUFFIXES[k])
        raise ModelError(f"{p}: is a directory, expected a {want} model file")
    return p


def default_model(kind: str = "onnx") -> Path:
    """Path of the shipped model of ``kind`` ('onnx' for the edge path, 'pt' for torch tools)."""
    return resolve_model(None, kinds=(kind,))


def _shipped(kind: str) -> tuple[Path, ...]:
    # looked up at call time, like `_default`
    return (_default(kind), FAST_ONNX if kind == "onnx" else FAST_CHECKPOINT)


def is_shipped_model(path: str | Path) -> bool:
    """Whether ``path`` is one of the shipped model files, the default or the fast option (decided by
    identity, not location).

    Why identity: in a source checkout the package directory is the maintainer's working tree
    (`edge.io.paths.package_roots` is empty there), yet tuning the shipped model must still not
    rewrite it silently; and a copy of it elsewhere is the user's own file.
    """
    p = Path(path)
    for kind in SUFFIXES:
        for d in _shipped(kind):
            try:
                if p.resolve() == d.resolve() or (p.exists() and d.exists() and os.path.samefile(p, d)):
                    return True
            except OSError:
                continue
    return False


def user_models_dir() -> Path:
    """Where commands put models derived from the shipped one: ``$XDG_DATA_HOME/depthseg/models``
    (``~/.local/share/depthseg/models`` when unset), never the installed package."""
    base = os.environ.get("XDG_DATA_HOME") or ""
    root = Path(base) if base and Path(base).is_absolute() else Path.home() / ".local" / "share"
    return root / "depthseg" / "models"
