"""How much a depth frame looks like a real pico flexx frame: numbers to put sim beside real.

Three families, each computed the same way on simulated and real frames (no labels needed, so
a real capture and a simulated frame go through identical code):

**Invalid pixels and where they lie.** Invalid = not finite or <= 0 (`edge.preprocess.valid_mask`).
Every invalid pixel falls in exactly one region, in this order:
- *corner*: outside the ellipse inscribed in the frame, ``((u-cu)/(W/2))^2 + ((v-cv)/(H/2))^2 > 1``
  with the frame centre (cu, cv); split into four quadrants (tl, tr, bl, br). This is where lens
  fall-off kills pixels (~21 % of the frame lies there);
- *edge*: within ``edge_radius`` px (a 7 x 7 window by default) of a depth discontinuity, i.e.
  the valid depths in the window span more than ``edge_step`` (20 mm): the pixels Royale's
  flying-pixel filter (or mixed returns) removed at object borders;
- *other*: the rest (random dead pixels, dark or saturated surfaces).
We report the overall fraction, the share of invalid pixels in each region, and per corner the
*fill*: the fraction of that corner region's pixels that are invalid.

**Floor noise sigma (spatial, from a single frame).** The floor is the dominant plane: RANSAC
on the back-projected valid pixels (seeded, 10 mm inlier band, refined by least squares), then
eroded by 2 px to keep away from object borders. Two estimates on it:
- ``sigma_patch``: the frame is cut into 8 x 8 tiles; on each tile lying wholly on the floor a
  plane ``Z = a u + b v + c`` is fitted and the residual std (n - 3 dof) taken; the median over
  tiles. It holds all noise at scales below ~8 px, correlated or not, and ignores slow floor
  deviations (multipath, residual distortion). This is the number to compare.
- ``sigma_diff``: 1.4826 x MAD of horizontal neighbour differences on the floor / sqrt(2). Only
  equal to sigma for white noise; spatial smoothing (Royale's 3x3 filter) lowers it, so the ratio
  ``sigma_diff / sigma_patch`` (1.0 for white noise) measures how correlated the noise is.

**Flying pixels at edges.** Edge pixels are valid pixels with a valid 4-neighbour more than
``step`` (18 mm, Royale's flying-pixel rule) away. A flying pixel is a valid pixel that differs
from both horizontal (or both vertical) valid neighbours by more than ``step`` and lies between
them (a mixed return, not a spike). We report flying / edge pixels. Royale invalidates exactly
these, so real frames show few; the invalid *edge* share above shows where they went.

**Edge sharpness, per object outline.** The edge-pixel count grows with how much object outline a
scene has (the real capture holds a 20 cm bottle and a brush; a Table I scene smaller boxes), so
it cannot compare a simulator's edge model with a sensor across scenes. *Outline* pixels are
valid pixels off the floor plane (more than the 10 mm band, the real capture's labelling rule)
with a floor pixel among their 4 neighbours; ``sharpness`` = edge pixels / outline pixels. A
blurred edge spreads each step over several pixels below the 18 mm rule and drives it towards 0;
an ideal step gives 2 (the pixels on both sides of it are edge pixels); a filter that removes the
mixed pixel between the two sides lowers it (the removed pixel's neighbours no longer compare).
``invalid_per_edge_pixel`` = invalid pixels of the *edge* region above per valid edge pixel: how
much the flying-pixel filter and mixed returns remove per pixel of edge.

Numpy only (no torch, no scipy): runs on the edge path and in tests.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, replace

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view

from edge.errors import DataError
from edge.meta import SensorSpec
from edge.preprocess import valid_mask

__all__ = [
    "CORNERS",
    "InvalidStats",
    "NoiseStats",
    "FlyingStats",
    "Realism",
    "corner_masks",
    "depth_discontinuity",
    "invalid_regions",
    "invalid_stats",
    "floor_mask",
    "floor_noise",
    "flying_pixels",
    "EdgeStats",
    "edge_sharpness",
    "realism",
]

CORNERS = ("tl", "tr", "bl", "br")
EDGE_STEP_M = 0.020
EDGE_RADIUS = 3
FLYING_STEP_M = 0.018  # Royale: invalid when off both horizontal (or vertical) neighbours by > 18 mm
FLOOR_BAND_M = 0.010
TILE = 8


def _default_intrinsics(shape: tuple[int, int]) -> tuple[float, float, float, float]:
    return SensorSpec().intrinsics_for_size(*shape)


def corner_masks(shape: tuple[int, int]) -> dict[str, np.ndarray]:
    """Boolean masks of the four corner regions (outside the inscribed ellipse, by quadrant)."""
    h, w = shape
    cv, cu = (h - 1) / 2.0, (w - 1) / 2.0
    v, u = np.mgrid[0:h, 0:w].astype(np.float64)
    outside = ((u - cu) / (w / 2.0)) ** 2 + ((v - cv) / (h / 2.0)) ** 2 > 1.0
    top, left = v < cv, u < cu
    return {
        "tl": outside & top & left,
        "tr": outside & top & ~left,
        "bl": outside & ~top & left,
        "br": outside & ~top & ~left,
    }


def _window_range(depth: np.ndarray, valid: np.ndarray, radius: int) -> np.ndarray:
    """max - min of the valid depths in each (2r+1)^2 window (0 where fewer than two are valid)."""
    k = 2 * radius + 1
    hi = np.pad(np.where(valid, depth, -np.inf), radius, constant_values=-np.inf)
    lo = np.pad(np.where(valid, depth, np.inf), radius, constant_values=np.inf)
    mx = sliding_window_view(hi, (k, k)).max(axis=(-1, -2))
    mn = sliding_window_view(lo, (k, k)).min(axis=(-1, -2))
    with np.errstate(invalid="ignore"):
        rng = mx - mn
    return np.where(np.isfinite(rng), rng, 0.0)


def depth_discontinuity(
    depth: np.ndarray, radius: int = EDGE_RADIUS, step: float = EDGE_STEP_M
) -> np.ndarray:
    """Pixels within ``radius`` of a depth jump larger than ``step`` (valid depths only)."""
    d = np.asarray(depth, dtype=np.float64)
    return _window_range(d, valid_mask(d), radius) > step


@dataclass(frozen=True)
class InvalidStats:
    """Where the invalid pixels are (shares sum to 1 when any pixel is invalid)."""

    fraction: float
    corner_share: float
    edge_share: float
    other_share: float
    corner_fill: dict[str, float]
    corner_area: float  # fraction of the frame that the corner regions cover


def invalid_regions(
    depth: np.ndarray, radius: int = EDGE_RADIUS, step: float = EDGE_STEP_M
) -> dict[str, np.ndarray]:
    """Masks of the invalid pixels in each region: ``corner``, ``edge``, ``other`` (disjoint)."""
    d = np.asarray(depth, dtype=np.float64)
    invalid = ~valid_mask(d)
    in_corner = np.zeros(d.shape, bool)
    for m in corner_masks(d.shape).values():
        in_corner |= m
    at_edge = depth_discontinuity(d, radius, step) & ~in_corner
    return {
        "corner": invalid & in_corner,
        "edge": invalid & at_edge,
        "other": invalid & ~in_corner & ~at_edge,
    }


def invalid_stats(depth: np.ndarray, radius: int = EDGE_RADIUS, step: float = EDGE_STEP_M) -> InvalidStats:
    """Invalid-pixel fraction and its split into corner / object-edge / other pixels."""
    d = np.asarray(depth, dtype=np.float64)
    invalid = ~valid_mask(d)
    corners = corner_masks(d.shape)
    regions = invalid_regions(d, radius, step)
    n = int(invalid.sum())

    def share(m: np.ndarray) -> float:
        return float(m.sum() / n) if n else 0.0

    return InvalidStats(
        fraction=float(invalid.mean()),
        corner_share=share(regions["corner"]),
        edge_share=share(regions["edge"]),
        other_share=share(regions["other"]),
        corner_fill={k: float(invalid[m].mean()) for k, m in corners.items()},
        corner_area=float(sum(m.sum() for m in corners.values()) / d.size),
    )


def floor_mask(
    depth: np.ndarray,
    intrinsics: tuple[float, float, float, float] | None = None,
    rng: np.random.Generator | None = None,
    band: float = FLOOR_BAND_M,
    iterations: int = 200,
) -> np.ndarray:
    """Pixels on the dominant plane (the floor): seeded RANSAC in 3-D, least-squares refit."""
    d = np.asarray(depth, dtype=np.float64)
    valid = valid_mask(d)
    if valid.sum() < 3:
        raise DataError("fewer than 3 valid pixels: no floor plane to fit")
    fx, fy, cx, cy = intrinsics or _default_intrinsics(d.shape)
    rng = rng if rng is not None else np.random.default_rng(0)
    vv, uu = np.nonzero(valid)
    z = d[valid]
    pts = np.stack([(uu - cx) / fx * z, (vv - cy) / fy * z, z], axis=1)
    best, best_n = None, -1
    for _ in range(iterations):
        a, b, c = pts[rng.choice(len(pts), 3, replace=False)]
        n = np.cross(b - a, c - a)
        norm = np.linalg.norm(n)
        if norm < 1e-12:
            continue
        n /= norm
        inl = np.abs((pts - a) @ n) < band
        k = int(inl.sum())
        if k > best_n:
            best, best_n = inl, k
    if best is None:
        raise DataError("valid pixels are collinear: no floor plane to fit")
    for _ in range(2):  # refit on the inliers (least squares), then re-select
        p = pts[best]
        centre = p.mean(axis=0)
        n = np.linalg.svd(p - centre, full_matrices=False)[2][2]
        best = np.abs((pts - centre) @ n) < band
    out = np.zeros(d.shape, bool)
    out[vv[best], uu[best]] = True
    return out


def _erode(mask: np.ndarray, iterations: int) -> np.ndarray:
    m = mask.copy()
    for _ in range(iterations):
        p = np.pad(m, 1, constant_values=False)
        m = m & p[:-2, 1:-1] & p[2:, 1:-1] & p[1:-1, :-2] & p[1:-1, 2:]
    return m


@dataclass(frozen=True)
class NoiseStats:
    """Spatial noise on the floor, metres."""

    sigma_patch: float
    sigma_diff: float
    tiles: int
    floor_fraction: float


def floor_noise(
    depth: np.ndarray,
    floor: np.ndarray | None = None,
    intrinsics: tuple[float, float, float, float] | None = None,
    rng: np.random.Generator | None = None,
    tile: int = TILE,
) -> NoiseStats:
    """Noise sigma on flat floor tiles (local plane residuals) and from neighbour differences."""
    d = np.asarray(depth, dtype=np.float64)
    if floor is None:
        floor = floor_mask(d, intrinsics, rng)
    floor = np.asarray(floor, bool) & valid_mask(d)
    core = _erode(floor, 2)
    h, w = d.shape
    th, tw = h // tile, w // tile
    blocks = d[: th * tile, : tw * tile].reshape(th, tile, tw, tile).transpose(0, 2, 1, 3).reshape(-1, tile * tile)
    ok = core[: th * tile, : tw * tile].reshape(th, tile, tw, tile).transpose(0, 2, 1, 3).reshape(-1, tile * tile)
    full = blocks[ok.all(axis=1)]
    if len(full):
        v, u = np.mgrid[0:tile, 0:tile].reshape(2, -1).astype(np.float64)
        a = np.stack([u, v, np.ones_like(u)], axis=1)
        resid = full - full @ (a @ np.linalg.pinv(a)).T
        sd = np.sqrt((resid**2).sum(axis=1) / (tile * tile - 3))
        sigma_patch = float(np.median(sd))
    else:
        sigma_patch = float("nan")
    pair = core[:, 1:] & core[:, :-1]
    diffs = (d[:, 1:] - d[:, :-1])[pair]
    if diffs.size:
        mad = np.median(np.abs(diffs - np.median(diffs)))
        sigma_diff = float(1.4826 * mad / np.sqrt(2.0))
    else:
        sigma_diff = float("nan")
    return NoiseStats(sigma_patch, sigma_diff, int(len(full)), float(floor.mean()))


@dataclass(frozen=True)
class FlyingStats:
    """Mixed returns at depth edges."""

    edge_pixels: int
    flying_pixels: int
    fraction: float  # flying / edge pixels (0 when there is no edge)


def flying_pixels(depth: np.ndarray, step: float = FLYING_STEP_M) -> tuple[FlyingStats, np.ndarray]:
    """(stats, mask of flying pixels) by Royale's both-neighbours rule, between-the-sides only."""
    d = np.asarray(depth, dtype=np.float64)
    valid = valid_mask(d)
    p = np.pad(np.where(valid, d, np.nan), 1, constant_values=np.nan)
    c = p[1:-1, 1:-1]
    left, right, up, down = p[1:-1, :-2], p[1:-1, 2:], p[:-2, 1:-1], p[2:, 1:-1]
    with np.errstate(invalid="ignore"):
        edge = valid & (
            (np.abs(c - left) > step) | (np.abs(c - right) > step) | (np.abs(c - up) > step) | (np.abs(c - down) > step)
        )

        def between(a: np.ndarray, b: np.ndarray) -> np.ndarray:
            return (np.abs(c - a) > step) & (np.abs(c - b) > step) & ((c - a) * (c - b) < 0)

        flying = valid & (between(left, right) | between(up, down))
    ne, nf = int(edge.sum()), int(flying.sum())
    return FlyingStats(ne, nf, nf / ne if ne else 0.0), flying


@dataclass(frozen=True)
class EdgeStats:
    """Edge statistics that do not grow with the scene's amount of edge (unlike the counts)."""

    outline_pixels: int
    sharpness: float  # edge pixels / outline pixels (nan when there is no outline)
    # invalid pixels in the object-edge region per valid edge pixel: how many pixels the flying-pixel
    # filter and mixed returns remove per pixel of edge (nan without edge pixels)
    invalid_per_edge_pixel: float = float("nan")


def edge_sharpness(
    depth: np.ndarray, floor: np.ndarray, step: float = FLYING_STEP_M, edge_pixels: int | None = None
) -> EdgeStats:
    """Edge pixels (4-neighbour step > ``step``) per outline pixel of the non-floor valid pixels.

    Args:
        depth: Z frame in metres, 0 or non-finite = invalid.
        floor: boolean mask of the floor plane's pixels (`floor_mask`).
        step: the edge-pixel rule's depth step in metres (Royale's 18 mm).
        edge_pixels: the frame's edge-pixel count when already known (`flying_pixels`), else
            counted here.
    """
    d = np.asarray(depth, dtype=np.float64)
    valid = valid_mask(d)
    fl = np.asarray(floor, bool) & valid
    p = np.pad(fl, 1, constant_values=False)
    touches_floor = p[:-2, 1:-1] | p[2:, 1:-1] | p[1:-1, :-2] | p[1:-1, 2:]
    outline = int((valid & ~fl & touches_floor).sum())
    edges = flying_pixels(d, step)[0].edge_pixels if edge_pixels is None else edge_pixels
    return EdgeStats(outline, edges / outline if outline else float("nan"))


@dataclass(frozen=True)
class Realism:
    """All realism numbers of one frame."""

    invalid: InvalidStats
    noise: NoiseStats
    flying: FlyingStats
    edges: EdgeStats

    def to_dict(self) -> dict:
        return asdict(self)


def realism(
    depth: np.ndarray,
    intrinsics: tuple[float, float, float, float] | None = None,
    seed: int = 0,
    floor: np.ndarray | None = None,
) -> Realism:
    """Invalid-pixel, floor-noise and flying-pixel statistics of one Z-depth frame (m, 0 invalid)."""
    d = np.asarray(depth, dtype=np.float64)
    if d.ndim != 2 or min(d.shape) < 2 * TILE:
        raise DataError(f"a depth frame must be 2-D and at least {2 * TILE} px a side, got {d.shape}")
    if floor is None:
        floor = floor_mask(d, intrinsics, np.random.default_rng(seed))
    flying = flying_pixels(d)[0]
    inv = invalid_stats(d)
    edges = edge_sharpness(d, floor, edge_pixels=flying.edge_pixels)
    edge_invalid = inv.edge_share * inv.fraction * d.size
    per_edge = edge_invalid / flying.edge_pixels if flying.edge_pixels else float("nan")
    return Realism(
        invalid=inv,
        noise=floor_noise(d, floor=floor, intrinsics=intrinsics),
        flying=flying,
        edges=replace(edges, invalid_per_edge_pixel=per_edge),
    )
