"""The ten held-out simulated sets a default is chosen by, and one sweep loop over them.

One list for every tool that chooses (`eval_ablation.py --candidates`, `speck_sweep.py`,
`height_gate_sweep.py`): the README results table's simulated sets, never the BlenSor or real
frames. `sweep` runs the model once per frame and scores every variant of the mask on the same
logits, so a sweep costs one inference per frame whatever the number of variants.
"""

from __future__ import annotations

import hashlib
import json
import sys
from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))

# (name, data) relative to the repo root; made by tools/results_table.py --make-data
HELD_OUT = [("own sim", "data/test_default"), ("crisp", "data/test_crisp"), ("blurred", "data/test_blurred"),
            *[(f, f"data/test_{f}") for f in ("thin", "table_edge", "tilted", "curved", "tray", "stacked", "long")]]

# sha256 of each held-out set as simulated when they were recorded (tools/ablation/heldout_digests.py --write)
DIGESTS = ROOT / "tools" / "ablation" / "heldout_digests.json"


def set_digest(path: Path) -> str:
    """sha256 over the frame files of one data set (an MCAP file, or a folder's ``*.mcap`` shards).

    Why: the held-out sets are simulated anew in every checkout, and a drop of objects is chaotic,
    so a set can differ across machines although seed, config and pinned versions agree (v20's
    scores moved 0.01-0.03 on 2026-12-06). Shard names and bytes are hashed in name order;
    ``manifest.json`` is left out, since it holds timings and the git commit.

    Args:
        path: a held-out set, as in `HELD_OUT` (relative paths are taken from the repo root).
    """
    path = ROOT / path
    files = [path] if path.is_file() else sorted(path.glob("*.mcap"))
    h = hashlib.sha256()
    for f in files:
        h.update(f.name.encode() + b"\0")
        with open(f, "rb") as fh:
            for block in iter(lambda: fh.read(1 << 20), b""):
                h.update(block)
    return h.hexdigest()


def digest_report(recorded: Path = DIGESTS, sets: Sequence[tuple[str, str]] = HELD_OUT) -> str:
    """One line saying whether the local held-out sets are the recorded ones, and which differ.

    A candidate's scores are comparable with the tables in BENCHMARKS.md to the last decimal only on
    the same frames; this line, printed under every choice table, says whether they are.

    Args:
        recorded: the JSON written by ``heldout_digests.py --write`` (``{"sets": {data: sha256}, ...}``).
        sets: (name, data) pairs to check.
    """
    if not recorded.exists():
        return f"held-out sets: no recorded digests ({recorded.name} missing; write them with heldout_digests.py --write)"
    rec = json.loads(recorded.read_text())
    present = [(n, d) for n, d in sets if (ROOT / d).exists()]
    differ = [n for n, d in present if rec["sets"].get(d) != set_digest(Path(d))]
    where = f"recorded {rec.get('date', '?')} on {rec.get('cpu', '?')}"
    if not differ:
        return f"held-out sets: {len(present)} of {len(sets)} present, all identical to {recorded.name} ({where})"
    return (f"held-out sets: {len(differ)} of {len(present)} present differ from {recorded.name} ({where}): "
            f"{', '.join(differ)}; their scores can differ from BENCHMARKS.md's by a few hundredths")


# a variant: (logits, valid, depth) -> bool object mask before scoring
Variant = Callable[[np.ndarray, np.ndarray, np.ndarray], np.ndarray]


def sweep(seg, heads: Sequence[str], variants: Sequence[Variant]) -> int:
    """Print a markdown table: one row per held-out set, one column per variant (mean IoU over
    frames, %), and the mean over the sets.

    Args:
        seg: an `edge.infer.Segmenter` (its logits are computed once per frame).
        heads: column titles, one per variant.
        variants: functions from (logits, valid, depth) to the object mask to score.
    """
    from edge.infer import checked_logits
    from edge.io import open_frames
    from edge.metrics import confusion, frame_scores
    from edge.preprocess import valid_mask

    print("| held-out set | " + " | ".join(heads) + " |")
    print("|---|" + "---:|" * len(heads))
    means: list[list[float]] = []
    for name, data in HELD_OUT:
        path = ROOT / data
        if not path.exists():
            print(f"| {name} | missing: simulate it with tools/results_table.py --make-data |")
            continue
        frames, _ = open_frames(path, require_labels=True)
        per: list[list[float]] = [[] for _ in variants]
        for fr in frames:
            d, lab = np.asarray(fr.depth), np.asarray(fr.label)
            valid = valid_mask(d)
            logits = checked_logits(seg, d)
            for i, variant in enumerate(variants):
                s = frame_scores(confusion(variant(logits, valid, d), lab, valid))
                if s is not None:
                    per[i].append(s.iou)
        row = [100 * float(np.mean(p)) for p in per]
        means.append(row)
        print(f"| {name} | " + " | ".join(f"{v:.2f}" for v in row) + " |", flush=True)
    if means:
        col = np.mean(np.asarray(means), axis=0)
        print(f"| mean of {len(means)} sets | " + " | ".join(f"{v:.2f}" for v in col) + " |")
    return 0
