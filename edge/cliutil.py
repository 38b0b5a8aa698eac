"""Shared plumbing for the thin ``main(argv) -> int`` CLIs.

Every console script wraps its body in `run`, so a `DepthsegError` (or a missing file, or an
unwritable output) becomes one line on stderr and exit code 2, never a traceback.

Library code never names a command-line flag: its messages name the parameter in backticks
(``"`labels_topic`"``), which is what a Python caller passes. `run` given the CLI's parser
rewrites each backticked parameter that is one of the parser's destinations into its flag
(``--labels-topic``), so a CLI user reads the flag to change.
"""

from __future__ import annotations

import argparse
import importlib
import importlib.util
import json
import re
import sys
from collections.abc import Callable, Iterable, Mapping
from typing import Any

from edge.errors import DepthsegError, MissingExtraError

__all__ = [
    "add_recording_args", "add_min_height_arg",
    "run", "fail", "print_json", "progress", "flag_names", "cli_message", "add_version", "require", "EXTRAS"]

# pip extras of pyproject.toml [project.optional-dependencies] -> the modules they provide
EXTRAS: dict[str, tuple[str, ...]] = {
    "train": ("torch", "onnx", "onnxscript", "matplotlib"),
    "sim": ("mujoco", "open3d", "scipy"),
    "ros": ("rosbags", "foxglove"),
    "ray": ("ray",),
}


def require(extra: str, modules: Iterable[str], what: str = "", load: bool = True) -> None:
    """Check at a command's start that ``modules`` import; else one line naming the pip extra.

    Why: a base install (``pip install depthseg``) runs the edge path only; a command that needs
    torch (training, export, a ``.pt`` model), open3d (the plane baseline) or matplotlib (plots)
    must say which extra to install before doing any work, not fail with a traceback halfway.
    The modules are really imported (a module that is present but broken, e.g. open3d without
    its system library, counts as missing); a command needs them anyway.

    Args:
        extra: the pip extra that provides them (``"train"``, ``"sim"``, ...).
        modules: top-level module names.
        what: what needs them, for the message (e.g. ``"a .pt model"``).
        load: import each module (True) or only find it (False: for modules that are slow to
            import and that subprocesses import themselves, such as the simulator's open3d).

    Raises:
        MissingExtraError: one line: what is missing, why it is needed, the pip command.
    """
    missing = []
    for name in modules:
        try:
            if load:
                importlib.import_module(name)
            elif importlib.util.find_spec(name) is None:
                raise ModuleNotFoundError(name)
        except (ImportError, OSError, ValueError) as exc:  # OSError: a missing shared library
            missing.append(name if isinstance(exc, ModuleNotFoundError) else f"{name} ({' '.join(str(exc).split())[:80]})")
    if missing:
        need = f" for {what}" if what else ""
        raise MissingExtraError(
            f"{', '.join(missing)} not installed{need}; install the extra: pip install 'depthseg[{extra}]'"
        )


def add_recording_args(parser: argparse.ArgumentParser, limit_help: str = "use at most N frames") -> None:
    """The flags every command that reads a labelled recording shares (eval, tune).

    ``--depth-topic``, ``--labels-topic`` (auto-detected by `edge.io.reader`), ``--depth-scale``,
    ``--limit`` and ``--threads``: one spelling and one help text for all of them.
    """
    from edge.io.frames import TOPIC_DEPTH, TOPIC_LABELS

    parser.add_argument("--depth-topic", default=None, help=f"depth Image topic (default: auto-detected, e.g. {TOPIC_DEPTH})")
    parser.add_argument(
        "--labels-topic", default=None,
        help=f"label Image topic, mono8 nonzero = object (default: auto-detected, e.g. {TOPIC_LABELS})",
    )
    parser.add_argument(
        "--depth-scale", type=float, default=1.0, metavar="S",
        help="multiply decoded depth by S (0.001: millimetres stored as 32FC1; default 1)",
    )
    parser.add_argument("--limit", type=int, default=None, metavar="N", help=limit_help)
    parser.add_argument("--threads", type=int, default=2, metavar="N", help="inference threads (default 2)")


def _millimetres_as_metres(text: str) -> float:
    from edge.cues import MAX_MIN_HEIGHT_M

    try:
        mm = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number of millimetres, got {text!r}") from None
    if not (0.0 <= mm <= MAX_MIN_HEIGHT_M * 1000):  # NaN fails too
        raise argparse.ArgumentTypeError(f"must be from 0 (off) to {MAX_MIN_HEIGHT_M * 1000:g} mm, got {text}")
    return mm / 1000.0


def add_min_height_arg(parser: argparse.ArgumentParser, store: bool = False) -> None:
    """``--min-height-mm MM`` (parsed to metres, ``args.min_height_m``; None = the model's rule).

    One flag for eval, replay, bench (``store`` False: this run only) and export (``store`` True:
    kept in the model's metadata); the rule is `edge.postprocess.remove_low_parts`.
    """
    what = "store in the exported model" if store else "for this run"
    parser.add_argument(
        "--min-height-mm", dest="min_height_m", type=_millimetres_as_metres, default=None, metavar="MM",
        help=f"{what}: object pixels lower than MM above the table become table, in objects that reach higher "
             "(objects wholly below stay); 10 gives the meaning of labels '> 10 mm above the floor plane'. "
             "Default: the model's rule (0 = off, the simulator's meaning, unless stored otherwise)",
    )


def add_version(parser: argparse.ArgumentParser, prog: str) -> None:
    """``--version``: package version and git commit (`edge.provenance`)."""

    class _Version(argparse.Action):
        def __init__(self, option_strings, dest=argparse.SUPPRESS, default=argparse.SUPPRESS, help=None):
            super().__init__(option_strings, dest=dest, default=default, nargs=0, help=help)

        def __call__(self, parser, namespace, values, option_string=None):
            from edge.provenance import version_string

            print(version_string(prog))
            parser.exit()

    parser.add_argument("--version", action=_Version, help="print the depthseg version and git commit, then exit")


def fail(prog: str, message: str, code: int = 2) -> int:
    print(f"{prog}: error: {message}", file=sys.stderr)
    return code


def flag_names(parser: argparse.ArgumentParser | None, aliases: Mapping[str, str] | None = None) -> dict[str, str]:
    """Parameter name -> the parser's flag for it (its first long option), plus ``aliases``."""
    out: dict[str, str] = {}
    todo = [parser] if parser is not None else []
    while todo:
        for action in todo.pop()._actions:
            if isinstance(action, argparse._SubParsersAction):
                todo.extend(action.choices.values())
            longs = [o for o in action.option_strings if o.startswith("--")]
            if longs:
                out.setdefault(action.dest, longs[0])
    out.update(aliases or {})
    return out


def cli_message(message: str, flags: Mapping[str, str]) -> str:
    """``message`` with every backticked parameter of ``flags`` replaced by its flag."""
    return re.sub(r"`([A-Za-z_][A-Za-z0-9_]*)`", lambda m: flags.get(m.group(1), m.group(0)), message)


def run(
    prog: str,
    body: Callable[[], int | None],
    parser: argparse.ArgumentParser | None = None,
    aliases: Mapping[str, str] | None = None,
) -> int:
    """Call ``body``; map user-fixable errors to a one-line message and a non-zero code.

    Args:
        prog: the command name that starts the message.
        body: the command's work; returns the exit code (None = 0).
        parser: the command's parser: backticked parameter names in messages become its flags.
        aliases: extra parameter -> flag names (a library parameter named differently from the flag).
    """
    try:
        rc = body()
        return 0 if rc is None else int(rc)
    except DepthsegError as exc:
        # one line whatever the message holds (a quoted library error may carry newlines)
        return fail(prog, " ".join(cli_message(str(exc), flag_names(parser, aliases)).split()))
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
