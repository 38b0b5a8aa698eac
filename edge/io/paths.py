"""The one rule for which paths a command may read and write.

Why: a hurried user who types ``--out`` equal to ``--model`` must not lose the model; a FIFO or a
device node given as an input must not hang the command, and given as an output must not be
replaced by a regular file (as root, ``--out /dev/null`` would replace /dev/null); and nothing
may write into the installed package (pip's RECORD check then fails). Every CLI checks its
inputs with `check_input_file` and its outputs with `check_outputs` before doing any work, and
`edge.io.atomic.atomic_write` refuses a non-regular target as a last line of defence.

Messages name the parameter in backticks (``"`out`"``): `edge.cliutil.run` turns that into the
command's flag.
"""

from __future__ import annotations

import os
import stat
from collections.abc import Iterable, Mapping
from pathlib import Path

from edge.errors import ConfigError, DataError

__all__ = ["check_input_file", "check_output_dir", "check_outputs", "package_roots", "special_kind"]

PathLike = str | os.PathLike


def special_kind(path: PathLike) -> str | None:
    """``"FIFO"``, ``"device"``, ``"socket"`` for such a node (links followed); None otherwise."""
    try:
        mode = os.stat(path).st_mode
    except OSError:
        return None
    if stat.S_ISFIFO(mode):
        return "FIFO"
    if stat.S_ISCHR(mode) or stat.S_ISBLK(mode):
        return "device"
    if stat.S_ISSOCK(mode):
        return "socket"
    return None


def check_input_file(path: PathLike, name: str, allow_special: bool = False, allow_dir: bool = False) -> Path:
    """``path`` as a Path if it is a readable input; else a one-line `DataError`.

    Args:
        path: the input the user named.
        name: its parameter name (backticked in the message, e.g. ``"model"``).
        allow_special: accept a FIFO or device (a stream the user asked for on purpose); a
            FIFO with no writer would otherwise block the command forever.
        allow_dir: accept a directory (commands that read every recording in a folder).
    """
    p = Path(path)
    if not p.exists():
        raise DataError(f"`{name}` {p}: no such file or directory")
    kind = special_kind(p)
    if kind is not None and not allow_special:
        raise DataError(f"`{name}` {p} is a {kind}, not a regular file; copy the data to a file first")
    if p.is_dir() and not allow_dir:
        raise DataError(f"`{name}` {p} is a directory; give a file")
    return p


def package_roots() -> list[Path]:
    """The installed depthseg package directories (edge, export, replay, sim).

    Empty in a source checkout (``pyproject.toml`` beside the packages): there a maintainer
    regenerates the shipped model in place (``tools/train_default.sh``), which is the point.
    """
    roots = [Path(__file__).resolve().parents[1]]  # edge/
    base = roots[0].parent
    if (base / "pyproject.toml").exists():
        return []
    for pkg in ("export", "replay", "sim"):
        if (base / pkg / "__init__.py").exists():
            roots.append(base / pkg)
    return roots


def _same(a: Path, b: Path) -> bool:
    try:
        return a.exists() and b.exists() and os.path.samefile(a, b)
    except OSError:
        return False


def _inside(path: Path, root: Path) -> bool:
    try:
        path.relative_to(root)
        return True
    except ValueError:
        return False


def check_outputs(outputs: Mapping[str, PathLike | None], inputs: Mapping[str, PathLike | Iterable[PathLike] | None]) -> None:
    """Refuse outputs that would destroy an input, replace a special file, or write into the package.

    Args:
        outputs: parameter name -> output path (None = not written).
        inputs: parameter name -> input path, or several (None = not given). A directory input
            protects every file below it.

    Raises:
        ConfigError: one line naming the output parameter, the path and the fix. Two outputs
        resolving to the same file are refused too.
    """
    ins: list[tuple[str, Path]] = []
    for name, value in inputs.items():
        if value is None:
            continue
        items = [value] if isinstance(value, (str, os.PathLike)) else list(value)
        ins.extend((name, Path(v)) for v in items if v is not None)
    seen: list[tuple[str, Path]] = []
    roots = package_roots()
    for name, value in outputs.items():
        if value is None:
            continue
        out = Path(value)
        resolved = out.resolve()
        kind = special_kind(out)
        if kind is not None:
            raise ConfigError(f"`{name}` {out} is a {kind}, not a regular file; give a new file name")
        if out.exists() and out.is_dir():
            raise ConfigError(f"`{name}` {out} is a directory; give a file name inside it")
        for in_name, inp in ins:
            r_in = inp.resolve()
            if resolved == r_in or _same(out, inp) or (inp.is_dir() and _inside(resolved, r_in)):
                raise ConfigError(f"`{name}` {out} would overwrite the input `{in_name}`; choose another output path")
        for other_name, other in seen:
            if resolved == other:
                raise ConfigError(f"`{name}` and `{other_name}` are the same file {out}; give each its own path")
        for root in roots:
            if _inside(resolved, root):
                raise ConfigError(
                    f"`{name}` {out} is inside the installed depthseg package ({root}); write to a path of your own"
                )
        seen.append((name, resolved))


def check_output_dir(
    path: PathLike | None, name: str, inputs: Mapping[str, PathLike | Iterable[PathLike] | None], probes: Iterable[str]
) -> None:
    """An output *directory* (figures, a training run, simulated shards): `check_outputs` for the files in it.

    Args:
        path: the directory (may not exist yet; None = not written).
        name: its parameter name.
        inputs: as for `check_outputs`.
        probes: names of files the command writes inside; each must pass `check_outputs`, so an
            existing FIFO or directory of that name inside is refused too.

    Raises:
        ConfigError: ``path`` is an existing file, or a file inside it would be refused.
    """
    if path is None:
        return
    p = Path(path)
    if p.exists() and not p.is_dir():
        raise ConfigError(f"`{name}` {p} is an existing file, not a directory; give a directory (or a new path)")
    for probe in probes:
        check_outputs({name: p / probe}, inputs)
