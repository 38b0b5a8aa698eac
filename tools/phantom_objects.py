#!/usr/bin/env python
"""How often does a method see an object on a bare support? Phantoms on the empty frames of a set.

Why: a robot that reaches for an object that is not there fails worse than one that misses a
pixel of an outline, and the IoU tables hide it (an empty frame with one false pixel scores 0, so
a few such frames move a mean by tenths, and ten held-out sets hold few empty frames). This counts,
on the frames whose labels hold no object, the frames where a method reports any object pixel,
split by the support the simulator drew (plain table, table edge with the floor below, tray; from
the frame's scene record, "unknown" for other recordings), with the median size of those phantoms.
Methods: each ONNX model as it runs (stored threshold and speck rule, `edge.infer.Segmenter`), and
the plane fit of ``depthseg-eval --baseline`` as printed and with the model's speck rule
(`edge.postprocess.remove_specks`) so that rule is not what separates them. Torch-free.

    .venv/bin/depthseg-sim --out data/test_empty --frames 600 --seed 5 --workers 2 \\
        --config tools/test_configs/empty_scenes.json
    .venv/bin/python tools/phantom_objects.py data/test_empty --model edge/models/default.onnx OLD.onnx
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from statistics import median

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from edge.baseline import PlaneBaseline, intrinsics_for  # noqa: E402
from edge.cliutil import print_json, run  # noqa: E402
from edge.errors import DataError  # noqa: E402
from edge.infer import Segmenter  # noqa: E402
from edge.io import open_frames  # noqa: E402
from edge.postprocess import remove_specks  # noqa: E402
from edge.preprocess import valid_mask  # noqa: E402

PROG = "phantom_objects"
KINDS = ("table", "table edge", "tray", "unknown")


def support_kind(scene: dict | None) -> str:
    """The support a simulated frame shows, from its scene record (``unknown`` without one)."""
    sup = scene.get("params", {}).get("support") if isinstance(scene, dict) else None
    if not isinstance(sup, dict):
        return "unknown"
    return "tray" if sup.get("tray") else ("table edge" if sup.get("table_edge") else "table")


def phantoms(data: Path, models: list[Path | None], limit: int | None = None) -> dict[str, dict[str, dict]]:
    """Per method and support kind: empty frames, frames with a phantom, median phantom pixels.

    Args:
        data: a labelled recording (file or folder); frames with object pixels are skipped.
        models: ONNX models (None: the shipped default); each is one method, named by its path.
        limit: read at most this many frames.

    Returns:
        ``{method: {kind: {"frames", "with_phantom", "median_px"}}}`` with the kinds that occur
        and ``all``; methods in order: the models, ``plane fit``, ``plane fit + specks``.

    Raises:
        DataError: no empty labelled frame in ``data``.
    """
    segs = {str(m) if m is not None else "default": Segmenter(m, threads=2) for m in models}
    base = PlaneBaseline()
    first = next(iter(segs.values()))
    min_px, sensor = first.min_object_px, first.meta.sensor  # the plane fit reads frames as the first model
    counts: dict[str, dict[str, list[int]]] = {}
    frames, _n = open_frames(data, extras=("scene",))
    seen = 0
    for fr in frames:
        if limit is not None and seen >= limit:
            break
        seen += 1
        if fr.label is None or fr.label.any():
            continue
        valid = valid_mask(fr.depth)
        kind = support_kind(fr.scene)
        px = {name: int(((s.predict(fr.depth).mask == 1) & valid).sum()) for name, s in segs.items()}
        plane = base.predict(fr.depth, intrinsics_for(fr.depth.shape, fr.info, sensor)).astype(bool) & valid
        px["plane fit"] = int(plane.sum())
        px["plane fit + specks"] = int(remove_specks(plane, min_px).sum())
        for name, n in px.items():
            for k in (kind, "all"):
                counts.setdefault(name, {}).setdefault(k, []).append(n)
    if not counts:
        raise DataError(f"{data}: no labelled frame without objects; simulate one with "
                        "--config tools/test_configs/empty_scenes.json")
    order = [k for k in (*KINDS, "all") if k in next(iter(counts.values()))]
    return {name: {k: {"frames": len(v), "with_phantom": sum(1 for n in v if n),
                       "median_px": median([n for n in v if n]) if any(v) else 0}
                   for k in order for v in [by_kind[k]]}
            for name, by_kind in counts.items()}


def table(res: dict[str, dict[str, dict]]) -> str:
    """Markdown: one row per support kind, one column per method ("frames with a phantom (median px)")."""
    names = list(res)
    kinds = list(next(iter(res.values())))
    lines = ["| support | empty frames | " + " | ".join(names) + " |", "|---|---:|" + "---:|" * len(names)]
    for k in kinds:
        n = res[names[0]][k]["frames"]
        cells = [f"{r[k]['with_phantom']} ({100 * r[k]['with_phantom'] / n:.1f} %, {r[k]['median_px']:g} px)"
                 for r in res.values()]
        lines.append(f"| {k} | {n} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog=PROG, description=__doc__.split("\n\n")[0])
    p.add_argument("data", type=Path, help="labelled recording (file or folder)")
    p.add_argument("--model", type=Path, nargs="+", default=[None], help="ONNX model(s) (default: the shipped one)")
    p.add_argument("--limit", type=int, default=None, help="read at most this many frames")
    p.add_argument("--json", action="store_true")
    args = p.parse_args(argv)

    def body() -> int:
        res = phantoms(args.data, args.model, args.limit)
        if args.json:
            print_json(res)
        else:
            print(table(res))
            print("\ncells: empty frames with any object pixel (share, median phantom pixels of those frames)")
        return 0

    return run(PROG, body, p)


if __name__ == "__main__":
    raise SystemExit(main())
