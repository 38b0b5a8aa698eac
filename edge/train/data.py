"""Labelled frames for training: loaded once from simulated MCAP, preprocessed per batch.

Why in memory: 10,000 frames of 171 x 224 float32 depth plus labels take ~2 GB, far less than
the machine has, and decoding MCAP every epoch would cost more than the CPU forward pass.
Preprocessing runs per batch through `edge.preprocess` (the one implementation), so what the
network sees in training is exactly what it sees in eval, export and replay.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from edge.errors import DataError
from edge.io.reader import DEFAULT_TOLERANCE_NS, open_frames
from edge.meta import ModelMeta
from edge.preprocess import preprocess_for

__all__ = ["FrameSet", "load_frames", "split_indices", "make_batch", "data_identity"]

MANIFEST_KEYS = ("tool", "seed", "frames", "config_digest", "engines", "provenance")  # what names a simulated set


@dataclass
class FrameSet:
    depth: np.ndarray  # float32 [N, H, W], metres, 0 invalid
    label: np.ndarray  # uint8 [N, H, W]

    def __len__(self) -> int:
        return len(self.depth)

    def subset(self, idx: np.ndarray) -> FrameSet:
        return FrameSet(self.depth[idx], self.label[idx])


def load_frames(
    paths: list[str | Path],
    limit: int | None = None,
    progress=None,
    depth_topic: str | None = None,
    labels_topic: str | None = None,
) -> FrameSet:
    """All labelled frames of one size from MCAP files/directories (unlabelled frames refused).

    Reads through `edge.io.open_frames`, the reader eval and tune use: topics detected (or
    named), labels paired with depth by header stamp within a tolerance, so every recording
    that ``depthseg-eval`` accepts also trains.

    Args:
        paths: .mcap files or directories of them.
        limit: stop after this many frames.
        progress: a tqdm-like object whose ``update(1)`` is called per frame.
        depth_topic: the depth Image topic (None: detected).
        labels_topic: the label Image topic (None: detected).

    Raises:
        DataError: a path has no labels, a frame has none, or frame sizes differ.
    """
    depths: list[np.ndarray] = []
    labels: list[np.ndarray] = []
    for path in paths:
        frames, _ = open_frames(path, depth_topic, labels_topic, require_labels=True)
        for fr in frames:
            if fr.label is None:
                raise DataError(
                    f"{path}: depth frame at log time {fr.stamp_ns} ns has no label within "
                    f"{DEFAULT_TOLERANCE_NS / 1e6:g} ms of its stamp; training needs every frame labelled "
                    "(a label image per depth frame: sensor_msgs/Image mono8, nonzero = object, on a topic named "
                    "like /camera/labels, with the depth's header stamp)"
                )
            if depths and fr.depth.shape != depths[0].shape:
                raise DataError(f"{path}: frames of different sizes {fr.depth.shape} vs {depths[0].shape}")
            depths.append(np.nan_to_num(fr.depth, nan=0.0, posinf=0.0, neginf=0.0).astype(np.float32))
            labels.append(fr.label.astype(np.uint8))
            if progress is not None:
                progress.update(1)
            if limit and len(depths) >= limit:
                break
        if limit and len(depths) >= limit:
            break
    if not depths:
        raise DataError(f"no labelled frames found in {[str(p) for p in paths]}")
    return FrameSet(np.stack(depths), np.stack(labels))


def data_identity(paths: list[str | Path]) -> list[dict]:
    """For each training path, what made it: the simulator manifest's identity, else just the path.

    Why: a model found on a robot months later should say which frames it learned from, down to
    the physics library's version (the simulator's frames change with it: `sim.dataset`). A
    recording or a folder without a readable ``manifest.json`` is named by its path only.

    Args:
        paths: the ``--data`` / ``--train-dir`` arguments, files or folders.
    """
    import json

    out: list[dict] = []
    for p in paths:
        rec: dict = {"path": str(p)}
        man = Path(p) / "manifest.json"
        try:
            m = json.loads(man.read_text()) if man.is_file() and man.stat().st_size < 64 * 1024 * 1024 else None
        except (OSError, ValueError):
            m = None
        if isinstance(m, dict):
            rec.update({k: m[k] for k in MANIFEST_KEYS if k in m})
        out.append(rec)
    return out


def split_indices(n: int, fractions: tuple[float, float, float], seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Deterministic shuffled train/val/test index split (the paper's 70/20/10 by default)."""
    if n < 3:
        raise DataError(f"need at least 3 frames to split into train/val/test, got {n}")
    perm = np.random.default_rng(seed).permutation(n)
    a = max(1, int(round(fractions[0] * n)))
    b = max(1, int(round(fractions[1] * n)))
    a = min(a, n - 2)
    return perm[:a], perm[a : a + b], perm[a + b :]


def make_batch(
    fs: FrameSet, idx: np.ndarray, meta: ModelMeta, rng: np.random.Generator | None = None
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(x [B,C,Hp,Wp], target [B,1,Hp,Wp], loss mask [B,1,Hp,Wp]); augment when ``rng`` is given.

    Augmentations a depth user would want and that keep the frame size: horizontal flip,
    vertical flip (together: a 180-degree rotation). A 90-degree rotation would change
    171 x 224 into 224 x 171, which the sensor never produces, so it is not used.
    """
    xs, ts, ms = [], [], []
    for i in idx:
        d, lab = fs.depth[i], fs.label[i]
        if rng is not None:
            if rng.random() < 0.5:
                d, lab = d[:, ::-1], lab[:, ::-1]
            if rng.random() < 0.5:
                d, lab = d[::-1, :], lab[::-1, :]
        p = preprocess_for(d, meta)
        hp, wp = p.x.shape[-2:]
        t = np.zeros((1, hp, wp), np.float32)
        m = np.zeros((1, hp, wp), np.float32)
        h, w = lab.shape
        t[0, :h, :w] = lab
        m[0, :h, :w] = p.valid
        xs.append(p.x)
        ts.append(t)
        ms.append(m)
    return np.stack(xs), np.stack(ts), np.stack(ms)
