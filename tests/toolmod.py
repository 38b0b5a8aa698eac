"""Load a script of ``tools/`` as a module, so its tests call ``main(argv)`` and its functions.

Why one helper: the tools are scripts, not a package (they run as ``.venv/bin/python
tools/X.py``), so every test of one loaded it by file location; this is that rule once.
"""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path
from types import ModuleType

TOOLS = Path(__file__).resolve().parents[1] / "tools"


def load_tool(relpath: str) -> ModuleType:
    """The module of ``tools/<relpath>`` (e.g. ``"ablation/eval_ablation.py"``), executed once per call.

    Args:
        relpath: path of the script below ``tools/``. Its folder is on ``sys.path`` while it
            loads, so a script that imports a neighbour as a top-level module (eval_ablation.py
            imports heldout.py) loads too.
    """
    path = TOOLS / relpath
    folder = str(path.parent)
    sys.path.insert(0, folder)
    try:
        spec = importlib.util.spec_from_file_location(path.stem, path)
        mod = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(mod)
    finally:
        sys.path.remove(folder)
    return mod
