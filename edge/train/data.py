"""Labelled frames for training: loaded once from simulated MCAP, preprocessed once or per batch.

Why in memory: 10,000 frames of 171 x 224 float32 depth plus labels take ~2 GB, far less than
the machine has, and decoding MCAP every epoch would cost more than the CPU forward pass.
Preprocessing runs through `edge.preprocess` (the one implementation), so what the network sees
in training is what it sees in eval, export and replay: either per batch from the raw frames
(`FrameSet`), or once per frame before the first epoch (`prepare_frames` -> `PreparedSet`), after
which `make_batch` only flips, pads and (optionally) crops.
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from edge.errors import ConfigError, DataError
from edge.io.reader import DEFAULT_TOLERANCE_NS, open_frames
from edge.meta import ModelMeta
from edge.preprocess import input_options, padded_shape, preprocess_for

__all__ = ["FrameSet", "PreparedSet", "PREPROCESS_MODES", "load_frames", "prepare_frames", "prepared_bytes", "preprocess_mode", "RESERVE_BYTES",
           "available_memory_bytes", "split_indices", "make_batch", "parse_crop", "check_crop", "data_identity",
           "shard_counts_digest"]

PREPROCESS_MODES = ("once", "per-batch")  # `depthseg-train --preprocess`: PreparedSet or FrameSet batches
MANIFEST_KEYS = ("tool", "seed", "frames", "config_digest", "engines", "provenance")  # what names a simulated set


@dataclass
class FrameSet:
    depth: np.ndarray  # float32 [N, H, W], metres, 0 invalid
    label: np.ndarray  # uint8 [N, H, W]
    # int64 [N]: frames of one settled scene share a number (views of it from several poses);
    # None or all different: every frame is its own scene (a recording, one view a scene)
    scene: np.ndarray | None = None

    def __len__(self) -> int:
        return len(self.depth)

    def subset(self, idx: np.ndarray) -> FrameSet:
        return FrameSet(self.depth[idx], self.label[idx], None if self.scene is None else self.scene[idx])


@dataclass
class PreparedSet:
    """Frames already preprocessed for one model input (`prepare_frames`); `make_batch` reads them.

    Why: preprocessing a frame (robust statistics and the dominant-plane fit of the height cue,
    `edge.cues`) costs ~0.6 ms, and per batch it ran again in every epoch for the same frames:
    epochs of the shipped recipe are x0.87-0.96 without it (BENCHMARKS.md, "preprocessing once").
    Once, it costs one pass before the first epoch.

    What differs from per-batch preprocessing: a flip is applied to the preprocessed channels
    instead of to the raw frame before preprocessing. The flip decisions are the same (the same
    draws of the same generator); the statistics and the plane fit are those of the unflipped
    frame, whose sparse sampling grids (every 4th / 6th pixel) fall on other pixels than the
    flipped frame's, so the inputs differ from per-batch ones by what that resampling changes in
    the fit, not by the geometry. Without augmentation the batches are identical.

    Memory: 2x the loaded frames with the height cue: 10 bytes a pixel (one standardised depth
    channel and each cue in float32, the valid mask, the label) against their 5 (float32 depth,
    uint8 label); ``--preprocess per-batch`` keeps the lower figure.
    """

    channels: np.ndarray  # float32 [N, 1 + len(cues), H, W]: standardised depth once, then each cue, unpadded
    valid: np.ndarray  # bool [N, H, W]: the pixels the loss counts
    label: np.ndarray  # uint8 [N, H, W]
    options: dict  # the `edge.preprocess` arguments it was made with (`input_options(meta)`)
    scene: np.ndarray | None = None  # as `FrameSet.scene`

    def __len__(self) -> int:
        return len(self.channels)

    def subset(self, idx: np.ndarray) -> PreparedSet:
        return PreparedSet(self.channels[idx], self.valid[idx], self.label[idx], self.options,
                           None if self.scene is None else self.scene[idx])


def prepared_bytes(frames: int, height: int, width: int, cues: int) -> int:
    """Bytes a `PreparedSet` of that many frames holds: float32 channels, bool valid, uint8 label.

    Args:
        frames: how many frames.
        height: frame height in pixels.
        width: frame width in pixels.
        cues: cue channels of the model input (`ModelMeta.cues`).
    """
    return frames * height * width * (4 * (1 + cues) + 2)


def available_memory_bytes() -> int | None:
    """MemAvailable of /proc/meminfo (Linux), after handing this process's freed heap back; None elsewhere.

    Why the trim first: loading builds one array per frame and then stacks them; glibc keeps the
    freed per-frame arrays on its heap, which MemAvailable counts as used although this process
    can reuse it (32,000 loaded frames: 11.3 GiB available before ``malloc_trim``, 17.3 after).
    """
    import ctypes

    try:
        ctypes.CDLL("libc.so.6").malloc_trim(0)
    except (OSError, AttributeError):  # not glibc: read the figure as it is
        pass
    try:
        with open("/proc/meminfo") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        return None
    return None


RESERVE_BYTES = 1 << 30  # left free beside the prepared frames: the model, its optimizer, batches, the trainer


def preprocess_mode(requested: str, frames: int, height: int, width: int, cues: int,
                    copies: int = 1) -> tuple[str, str | None]:
    """(the mode to train with, a one-line reason when it is not ``requested``).

    "once" falls back to "per-batch" when its prepared frames (`prepared_bytes`) would not fit
    in the available memory less `RESERVE_BYTES`: the run then trains slower instead of failing.

    Args:
        requested: one of `PREPROCESS_MODES`.
        frames: training plus validation frames.
        height: frame height in pixels.
        width: frame width in pixels.
        cues: cue channels of the model input.
        copies: processes on this machine that each prepare the same frames (torchrun's
            ``LOCAL_WORLD_SIZE``: every rank holds the whole prepared set, `edge.train.distributed`),
            so that ranks starting together cannot each pass a check that together they fail.
    """
    if requested != "once":
        return requested, None
    copies = max(int(copies), 1)
    need, free = copies * prepared_bytes(frames, height, width, cues), available_memory_bytes()
    if free is None or need <= free - RESERVE_BYTES:
        return "once", None
    who = f" ({copies} processes on this machine, each a copy)" if copies > 1 else ""
    return "per-batch", (f"preprocessing {frames} frames once would take {need / 2**30:.1f} GiB{who} of the "
                         f"{free / 2**30:.1f} GiB available; preprocessing per batch instead (as --preprocess "
                         "per-batch: slower epochs, less memory)")


def prepare_frames(fs: FrameSet, meta: ModelMeta, idx: np.ndarray | None = None, progress=None) -> PreparedSet:
    """Preprocess frames of ``fs`` once for the input ``meta`` describes (see `PreparedSet`).

    Args:
        fs: the loaded frames.
        meta: the model whose input is made (channels, standardisation, cues, range, padding).
        idx: which frames, in this order (None: all); so a split needs no copy of the raw frames.
        progress: a tqdm-like object whose ``update(1)`` is called per frame.
    """
    idx = np.arange(len(fs)) if idx is None else np.asarray(idx)
    opts = input_options(meta)
    h, w = fs.depth.shape[1:]
    channels = np.empty((len(idx), 1 + len(opts["cues"]), h, w), np.float32)
    valid = np.empty((len(idx), h, w), bool)
    for j, i in enumerate(idx):
        p = preprocess_for(fs.depth[i], meta)
        channels[j] = _frame_channels(p, meta, h, w)
        valid[j] = p.valid
        if progress is not None:
            progress.update(1)
    return PreparedSet(channels, valid, fs.label[idx], opts, None if fs.scene is None else fs.scene[idx])


def _scene_key(k: int, pos: int, scene: dict | None) -> tuple:
    """Which settled scene frame ``pos`` of path ``k`` shows: the simulator's scene index when
    it drew several views of one scene (``params.view.scene_index``), else the frame itself."""
    params = scene.get("params") if isinstance(scene, dict) else None
    view = params.get("view") if isinstance(params, dict) else None
    if isinstance(view, dict) and isinstance(view.get("scene_index"), int):
        return (k, "scene", view["scene_index"])
    return (k, "frame", pos)


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
    scenes: dict[tuple, int] = {}
    scene_of: list[int] = []
    for k, path in enumerate(paths):
        frames, _ = open_frames(path, depth_topic, labels_topic, require_labels=True, extras=("scene",))
        for pos, fr in enumerate(frames):
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
            scene_of.append(scenes.setdefault(_scene_key(k, pos, fr.scene), len(scenes)))
            if progress is not None:
                progress.update(1)
            if limit and len(depths) >= limit:
                break
        if limit and len(depths) >= limit:
            break
    if not depths:
        raise DataError(f"no labelled frames found in {[str(p) for p in paths]}")
    return FrameSet(np.stack(depths), np.stack(labels), np.asarray(scene_of, dtype=np.int64))


def data_identity(paths: list[str | Path]) -> list[dict]:
    """For each training path, what made it: the simulator manifest's identity, else just the path.

    Why: a model found on a robot months later should say which frames it learned from, down to
    the physics library's version (the simulator's frames change with it: `sim.dataset`). A
    recording or a folder without a readable ``manifest.json`` is named by its path only.

    Args:
        paths: the ``--data`` / ``--train-dir`` arguments, files or folders.
    """

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
            counts = shard_counts_digest(m.get("shards"))
            if counts is not None:
                rec["shard_counts_digest"] = counts
        out.append(rec)
    return out


SHARD_COUNT_KEYS = ("file", "frames", "pixels", "object_pixels", "invalid_pixels")  # not "seconds": timings vary


def shard_counts_digest(shards) -> str | None:
    """sha256 of each shard's name and pixel counts in a simulator manifest, or None without them.

    Why: the same seed, config and engines made other frames on a CPU with AVX-512 than without
    (BENCHMARKS.md, "candidate nb8, results": all ten held-out sets differ from their digests), and
    a retrained model could not say whether it saw the shipped model's frames without those
    gigabytes at hand. The object and invalid pixel counts of every shard change with any change of
    a drop or of the sensor model, so equal digests mean the same frames in all but a vanishing
    case, and unequal ones mean other frames; it costs no read of a frame.

    Args:
        shards: the manifest's ``shards`` mapping (file name -> its record).
    """
    if not isinstance(shards, dict) or not shards:
        return None
    rows = []
    for name in sorted(shards):
        rec = shards[name]
        if not isinstance(rec, dict) or any(k not in rec for k in SHARD_COUNT_KEYS):
            return None
        rows.append([rec[k] for k in SHARD_COUNT_KEYS])
    return hashlib.sha256(json.dumps(rows, separators=(",", ":")).encode()).hexdigest()


def split_indices(n: int, fractions: tuple[float, float, float], seed: int,
                  scene: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Deterministic shuffled train/val/test index split (the paper's 70/20/10 by default).

    Why by scene: the simulator draws 4 camera views of each settled scene by default, and a
    split that draws frames puts nearly every validation frame's scene in the training set from
    another pose, so validation measured seen scenes (BENCHMARKS.md, candidate v11). With
    ``scene`` the scenes are shuffled and dealt whole to train, then validation, then test,
    each until it holds its share of the frames. When every frame is its own scene this is the
    frame split, index for index.

    Args:
        n: number of frames.
        fractions: train, validation and test shares, summing to 1.
        seed: the shuffle's seed.
        scene: int [n] scene number of each frame (`FrameSet.scene`), or None to split frames.
    """
    if n < 3:
        raise DataError(f"need at least 3 frames to split into train/val/test, got {n}")
    a = max(1, int(round(fractions[0] * n)))
    b = max(1, int(round(fractions[1] * n)))
    a = min(a, n - 2)
    if scene is None:
        perm = np.random.default_rng(seed).permutation(n)
        return perm[:a], perm[a : a + b], perm[a + b :]
    scene = np.asarray(scene)
    if scene.shape != (n,):
        raise DataError(f"`scene` must hold one number per frame ({n}), got shape {scene.shape}")
    ids, first, inverse = np.unique(scene, return_index=True, return_inverse=True)
    if len(ids) < 3:
        raise DataError(f"need at least 3 scenes to split into train/val/test, got {len(ids)}")
    g = len(ids)
    ordinal = np.argsort(np.argsort(first, kind="stable"), kind="stable")[inverse.ravel()]  # by first frame
    order = np.random.default_rng(seed).permutation(g)  # the frame split's permutation, of scenes
    place = np.empty(g, np.int64)
    place[order] = np.arange(g)
    frames_in_order = np.lexsort((np.arange(n), place[ordinal]))  # scenes dealt in `order`, O(n log n)
    ends = np.cumsum(np.bincount(ordinal, minlength=g)[order])
    # deal whole scenes: train takes scenes until it holds >= a frames, validation until >= a + b
    cut_a = min(int(np.searchsorted(ends, a)) + 1, len(order) - 2)
    cut_b = min(max(int(np.searchsorted(ends, a + b)) + 1, cut_a + 1), len(order))
    ia, ib = int(ends[cut_a - 1]), int(ends[cut_b - 1])
    return frames_in_order[:ia], frames_in_order[ia:ib], frames_in_order[ib:]


def make_batch(
    fs: FrameSet | PreparedSet, idx: np.ndarray, meta: ModelMeta, rng: np.random.Generator | None = None,
    crop: tuple[int, int] | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(x [B,C,Hp,Wp], target [B,1,Hp,Wp], loss mask [B,1,Hp,Wp]); augment when ``rng`` is given.

    Augmentations a depth user would want and that keep the frame's geometry: horizontal flip,
    vertical flip (together: a 180-degree rotation). A 90-degree rotation would change
    171 x 224 into 224 x 171, which the sensor never produces, so it is not used.

    ``crop`` (optional, with ``rng``): a random window of each frame as the network sees it
    (after its flips, preprocessed whole and padded), so standardisation and the height cue's plane
    fit still see the whole frame, and the zero band that pads 171 rows to 192 at inference is in
    the windows at the bottom. Why: a training step costs about what its pixels cost (a 128 x 160
    window steps ~2.2x faster than the padded 192 x 224 frame on the 2-core AMD EPYC), and the
    retraining recipe has a 60-minute budget (issue 9). Why the padded frame: windows of the
    unpadded frame never show that band, and a model trained so erred 3x as often on the frame's
    last 16 rows as in its middle (BENCHMARKS.md "candidate C"). The window's corner is drawn so
    that each border of the padded frame is in a quarter of the windows (`_draw_window`): uniform
    corners would show the outer rows and columns (the dead corners, objects cut by the border,
    the padding) in ~2 % of the windows.

    Args:
        fs: raw frames (preprocessed here) or a `PreparedSet` made for the same input.
        idx: which frames.
        meta: the model whose input is made.
        rng: draws the flips (two draws per frame, in order), then, with ``crop``, the window's
            top and left; None = no augmentation.
        crop: (height, width) of the window, at most the frame's, sides multiples of
            ``meta.pad_multiple``; None = whole frames. Needs ``rng``.
    """
    if crop is not None and rng is None:
        raise DataError("a crop window is drawn at random: give make_batch an rng with crop")
    if crop is not None:
        check_crop(crop, tuple(fs.label.shape[1:]), meta.pad_multiple)
    items = []  # per frame: (stored channels [1 + cues, H, W], label, valid), flipped
    corners: list[tuple[int, int]] = []  # with crop: each frame's window (top, left) in the padded frame
    if isinstance(fs, PreparedSet):
        if fs.options != input_options(meta):
            raise DataError(
                f"frames were preprocessed for {fs.options}, but the model reads {input_options(meta)}; "
                "prepare them again with this model's metadata (prepare_frames)"
            )
        h, w = fs.label.shape[1:]
        for i in idx:
            lr, ud = _draw_flips(rng)
            items.append((_flipped(fs.channels[i], lr, ud), _flipped(fs.label[i], lr, ud),
                          _flipped(fs.valid[i], lr, ud)))
            if crop is not None:
                corners.append(_draw_window(rng, (h, w), padded_shape(h, w, meta.pad_multiple), crop))
    else:
        h, w = fs.label.shape[1:]
        for i in idx:
            lr, ud = _draw_flips(rng)
            p = preprocess_for(_flipped(fs.depth[i], lr, ud), meta)
            items.append((_frame_channels(p, meta, h, w), _flipped(fs.label[i], lr, ud), p.valid))
            if crop is not None:
                corners.append(_draw_window(rng, (h, w), padded_shape(h, w, meta.pad_multiple), crop))
    batch = _assemble(items, meta, h, w)
    if crop is None:
        return batch
    ch, cw = crop
    return tuple(  # type: ignore[return-value]
        np.stack([a[b, :, top : top + ch, left : left + cw] for b, (top, left) in enumerate(corners)])
        for a in batch
    )


def parse_crop(text: str | None) -> tuple[int, int] | None:
    """``--crop HxW`` (e.g. "128x160") as (height, width); None when ``text`` is None.

    Args:
        text: the option's value as typed.
    """
    if text is None:
        return None
    parts = text.lower().split("x")
    if len(parts) != 2 or not all(v.strip().isdigit() and int(v) >= 1 for v in parts):
        raise ConfigError(f"--crop must be HEIGHTxWIDTH in pixels, e.g. 128x160; got '{text}'")
    return int(parts[0]), int(parts[1])


def check_crop(crop: tuple[int, int], frame: tuple[int, int], multiple: int = 1) -> None:
    """Raise `DataError` unless a (height, width) window fits the (height, width) frames.

    Args:
        crop: the window.
        frame: the frames' unpadded size.
        multiple: the model's `pad_multiple` (its total stride, 32), which the window's sides must
            be multiples of, since a window is fed to the network unpadded.
    """
    if crop[0] % multiple or crop[1] % multiple:
        raise DataError(
            f"crop {crop[0]}x{crop[1]}: height and width must be multiples of {multiple} (the network's stride), "
            "e.g. 128x160"
        )
    if crop[0] > frame[0] or crop[1] > frame[1]:
        raise DataError(
            f"crop {crop[0]}x{crop[1]} is larger than the frames ({frame[0]}x{frame[1]}); "
            f"give a window of at most {frame[0]}x{frame[1]} (height x width)"
        )


def _draw_window(rng: np.random.Generator, frame: tuple[int, int], padded: tuple[int, int],
                 crop: tuple[int, int]) -> tuple[int, int]:
    """(top, left) of a ``crop`` window in the ``padded`` frame: two draws, top then left.

    Each corner coordinate is drawn uniformly from the slack widened by half of it on both sides
    and clipped back, so the window touches each border of the padded frame in ~1/4 of the draws
    (the frame's top row is in ~26 % of 128-row windows instead of ~2 %) and every position
    between stays equally likely; a window never starts below the ``frame``'s last row or right
    of its last column, so it always holds some of the frame.
    """
    out = []
    for size, pad, c in zip(frame, padded, crop):
        slack = pad - c
        half = slack // 2
        out.append(min(int(np.clip(rng.integers(-half, slack + half + 1), 0, slack)), size - 1))
    return out[0], out[1]


def _draw_flips(rng: np.random.Generator | None) -> tuple[bool, bool]:
    """(left-right, up-down): two draws per frame, in that order; no flips without ``rng``."""
    if rng is None:
        return False, False
    return bool(rng.random() < 0.5), bool(rng.random() < 0.5)


def _flipped(a: np.ndarray, lr: bool, ud: bool) -> np.ndarray:
    """A view of ``a`` flipped over its last two axes (width, then height)."""
    if lr:
        a = a[..., ::-1]
    if ud:
        a = a[..., ::-1, :]
    return a


def _frame_channels(p, meta: ModelMeta, h: int, w: int) -> np.ndarray:
    """float32 [1 + cues, H, W] of an `edge.preprocess.Preprocessed`: the depth once, each cue; unpadded."""
    return np.concatenate([p.x[:1, :h, :w], p.x[meta.in_channels:, :h, :w]])


def _assemble(items: list[tuple[np.ndarray, np.ndarray, np.ndarray]], meta: ModelMeta, h: int,
              w: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The padded batch (x, target, mask) of frames' stored channels: depth replicated, padding 0."""
    ch = meta.in_channels
    hp, wp = padded_shape(h, w, meta.pad_multiple)
    n = len(items)
    x = np.zeros((n, ch + len(meta.cues), hp, wp), np.float32)  # padding stays 0, as in `preprocess`
    t = np.zeros((n, 1, hp, wp), np.float32)
    m = np.zeros((n, 1, hp, wp), np.float32)  # padding never reaches the loss
    for b, (c, lab, val) in enumerate(items):
        x[b, :ch, :h, :w] = c[0]
        x[b, ch:, :h, :w] = c[1:]
        t[b, 0, :h, :w] = lab
        m[b, 0, :h, :w] = val
    return x, t, m
