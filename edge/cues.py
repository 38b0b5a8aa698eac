"""Input cues beside standardised depth: height above the dominant plane, robust statistics.

Why a height cue: a robotics engineer's first tool is a floor-plane fit, and it wins wherever
the learned model has memorised the simulator's sensor instead of the geometry (issue 9: a 1-2 px
halo of false object pixels on BlenSor scans and real captures). Giving the network the height
above a robustly fitted dominant plane lets it start from that geometry and spend its capacity on
what a plane fit cannot do (thin objects in noise, edges, trays, table edges).

How, cheaply and without intrinsics: for a pinhole camera a plane n.X = d seen at pixel (u, v)
has inverse depth ``1 / Z = a u + b v + c``: affine in the pixel coordinates, whatever the
focal length. So the plane is fitted in (u, v, 1/Z) on a sparse pixel grid:

1. RANSAC with a fixed table of ``N_HYPOTHESES`` point triplets (fractions of the valid-point
   count, drawn once from a fixed seed): deterministic, and the same table is a constant in the
   ``--with-preprocessing`` ONNX graph.
2. Score = inliers (|Z - Z_plane| < ``INLIER_M``) - ``BEYOND_WEIGHT`` x the points that
   cannot lie on or above that support:
   - points ``BEYOND_M`` to ``REACH_M`` *behind* the plane: a support surface has nothing just
     under it in view, so a box top (with the table visible behind it) loses to the table even
     when it covers more pixels;
   - points more than ``REACH_M`` *in front of* it: nothing stands 30 cm tall on a support a
     wrist camera sees from 20-40 cm, so a floor past a table edge, with the table and
     everything on it far in front of it, loses to the table even when more floor than free
     table is in view (before this term it won: docs/worst, frame 703 of the validation set).
   Points more than ``REACH_M`` behind the plane do not count against it: that is the floor past
   the edge of a table.
3. Two least-squares refinements on the inliers, in inverse depth.

The cue is ``HEIGHT_SCALE`` x (Z_plane - Z) (centimetres above the plane along the optical axis),
clipped to ``HEIGHT_CLIP``, 0 at invalid pixels. Without a plane (fewer than ``MIN_POINTS`` valid
grid points, or no usable hypothesis) the plane is the constant median depth.

Numpy only: this module is on the edge path and must not import torch.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache

import numpy as np

__all__ = [
    "CUES",
    "PlaneFit",
    "fit_dominant_plane",
    "height_cue",
    "steepness_cue",
    "robust_mean_std",
    "zero_where_invalid",
    "det3",
    "GRID_STRIDE",
    "N_HYPOTHESES",
    "MAX_MIN_HEIGHT_M",
]

CUES = ("height", "steepness")  # the cue channels a model may ask for, in ModelMeta.cues

GRID_STRIDE = 6  # sparse grid for the fit: 29 x 38 points on a 171 x 224 frame
N_HYPOTHESES = 64
MIN_POINTS = 12
INLIER_M = 0.008  # the baseline's 8 mm: noise of the sensor (SENSOR.md) and BlenSor's 4 mm sigma
BEYOND_M = 0.03
BEYOND_WEIGHT = 0.5
REACH_M = 0.3  # objects stand at most this high on a support seen from 20-40 cm (HEIGHT_CLIP's top)
REFINE_ITERS = 2
HEIGHT_SCALE = 100.0  # metres -> centimetres
HEIGHT_CLIP = (-10.0, 30.0)
# highest line of the minimum-object-height rule (`edge.postprocess.remove_low_parts`): well under
# the clip's 30 cm, where every height reads the same
MAX_MIN_HEIGHT_M = 0.2
TRIM = (0.01, 0.99)  # robust standardisation: quantiles kept
STATS_STRIDE = 4  # robust standardisation reads every 4th pixel in each direction


@lru_cache(maxsize=1)
def hypothesis_table() -> np.ndarray:
    """(N_HYPOTHESES, 3) fractions in [0, 1): point i of a triplet is floor(f * n_points)."""
    return np.random.default_rng(20261130).random((N_HYPOTHESES, 3))


@dataclass(frozen=True)
class PlaneFit:
    """Inverse depth ``1/Z = a * u + b * v + c`` (u, v in pixels); ``ok`` False = fallback."""

    a: float
    b: float
    c: float
    ok: bool
    inlier_share: float

    def depth(self, shape: tuple[int, int]) -> np.ndarray:
        """Plane depth Z at every pixel (float32); 1e6 m where the plane lies behind the camera."""
        h, w = shape
        inv = np.add(np.float32(self.a) * _arange(w)[None, :], np.float32(self.b) * _arange(h)[:, None])
        inv += np.float32(self.c)
        # rounding is monotone, so the float32 plane is monotone along each axis and its smallest
        # value is at a corner: the clamp runs only when a corner needs it (it is 17 us a frame)
        eps = np.float32(1e-6)
        if min(inv[0, 0], inv[0, -1], inv[-1, 0], inv[-1, -1]) <= eps:
            np.maximum(inv, eps, out=inv)
        return np.divide(np.float32(1.0), inv, out=inv)


@lru_cache(maxsize=8)
def _arange(n: int) -> np.ndarray:
    return np.arange(n, dtype=np.float32)


@lru_cache(maxsize=8)
def _grid_coords(rows: int, cols: int, stride: int) -> tuple[np.ndarray, np.ndarray]:
    """float64 pixel coordinates (u, v) of a ``rows`` x ``cols`` grid of step ``stride`` (read-only)."""
    v, u = np.mgrid[0:rows, 0:cols]
    u, v = (u * stride).astype(np.float64), (v * stride).astype(np.float64)
    u.flags.writeable = v.flags.writeable = False
    return u, v


def _grid(depth: np.ndarray, valid: np.ndarray, stride: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(u, v, z) float64 of the valid points of the sparse grid, in row-major order."""
    g = valid[::stride, ::stride]
    uu, vv = _grid_coords(*g.shape, stride)
    return uu[g], vv[g], depth[::stride, ::stride][g].astype(np.float64)


def _solve3(u: np.ndarray, v: np.ndarray, q: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Planes through point triplets (rows) by Cramer's rule: (a, b, c, ok)."""
    u1, u2, u3 = u.T
    v1, v2, v3 = v.T
    q1, q2, q3 = q.T
    det = u1 * (v2 - v3) - v1 * (u2 - u3) + (u2 * v3 - u3 * v2)
    ok = np.abs(det) > 1.0  # pixel units: triplets spanning less than ~1 px^2 are degenerate
    d = np.where(ok, det, 1.0)
    a = (q1 * (v2 - v3) - v1 * (q2 - q3) + (q2 * v3 - q3 * v2)) / d
    b = (u1 * (q2 - q3) - q1 * (u2 - u3) + (u2 * q3 - u3 * q2)) / d
    c = (u1 * (v2 * q3 - v3 * q2) - v1 * (u2 * q3 - u3 * q2) + q1 * (u2 * v3 - u3 * v2)) / d
    return a, b, c, ok


def _count_rows(mask: np.ndarray) -> np.ndarray:
    """True values per row of a 2-D bool array, int64 (``np.count_nonzero(mask, axis=1)``, 3x faster).

    Why uint16 sums: adding the bytes into 16-bit lanes is another 3x faster than into int64 ones
    (8 against 25 us for the fit's 64 x ~1,000 grid on a 2-core AMD EPYC); rows too long for 16 bits
    take int64.
    """
    wide = mask.shape[1] >= 1 << 16
    return np.add.reduce(mask.view(np.uint8), axis=1, dtype=np.int64 if wide else np.uint16).astype(np.int64)


def det3(a1, b1, c1, a2, b2, c2, a3, b3, c3):
    """Determinant of the 3 x 3 matrix of rows (a_i, b_i, c_i), term by term.

    One expansion for the numpy fit (on exact integers, `_lstsq`) and the ``--with-preprocessing``
    graph (on float64 tensors, Cramer's rule, `export.preproc_graph`): any operands with ``*`` and ``-``.
    """
    return a1 * (b2 * c3 - c2 * b3) - b1 * (a2 * c3 - c2 * a3) + c1 * (a2 * b3 - b2 * a3)


def _lstsq(u: np.ndarray, v: np.ndarray, q: np.ndarray) -> tuple[float, float, float] | None:
    """Least-squares plane ``q = a u + b v + c`` (normal equations); None if they are singular.

    u and v are whole pixel coordinates, so every sum of the matrix is a whole number, exact in
    float64: its determinant is taken exactly in integers (a collinear set of points is singular
    for certain, where a floating-point determinant leaves a residue), then LAPACK solves.
    """
    n = len(q)
    if n < 3:
        return None
    su, sv, suu, suv, svv = float(u.sum()), float(v.sum()), float(u @ u), float(u @ v), float(v @ v)
    if det3(*(int(x) for x in (suu, suv, su, suv, svv, sv, su, sv, n))) == 0:
        return None
    ata = np.array([[suu, suv, su], [suv, svv, sv], [su, sv, float(n)]])
    sol = np.linalg.solve(ata, np.array([u @ q, v @ q, q.sum()]))
    return float(sol[0]), float(sol[1]), float(sol[2])


def fit_dominant_plane(depth: np.ndarray, valid: np.ndarray, stride: int = GRID_STRIDE) -> PlaneFit:
    """The dominant support plane of one frame (see the module docstring for the rule).

    Args:
        depth: [H, W] Z in metres.
        valid: [H, W] bool, pixels that returned a range.
        stride: grid step of the sparse sample used for the fit.

    Returns:
        The fitted plane; ``ok`` is False when the frame has too few valid points, and the plane
        is then the constant median depth of the valid pixels (or 1 m without any).
    """
    u, v, z = _grid(depth, valid, stride)
    n = len(z)
    if n < MIN_POINTS:
        med = float(np.median(depth[valid])) if valid.any() else 1.0
        return PlaneFit(0.0, 0.0, 1.0 / max(med, 1e-6), False, 0.0)
    q = 1.0 / z
    idx = np.minimum((hypothesis_table() * n).astype(np.int64), n - 1)
    a, b, c, ok = _solve3(u[idx], v[idx], q[idx])
    u32, v32, z32 = u.astype(np.float32), v.astype(np.float32), z.astype(np.float32)
    # r = z - 1 / max(a u + b v + c, 1e-6) for every hypothesis x point, in two float32 buffers
    # (the same operations in the same order as the plain expression: identical values, half
    # the time, which matters because this runs on every frame at the edge); the outer products
    # by einsum, one rounded product each like the broadcast multiply, 0.7x its time
    r = np.einsum("i,j->ij", a.astype(np.float32), u32)
    tmp = np.einsum("i,j->ij", b.astype(np.float32), v32)
    r += tmp
    r += c.astype(np.float32)[:, None]
    ok &= r.min(axis=1) > 1e-6
    # max(., 1e-6) changes only rows with a point at or behind the camera, which are not ``ok``
    # and score -inf whatever their residuals: so it is skipped (34 us), and 1/0 ignored
    with np.errstate(divide="ignore", over="ignore", invalid="ignore"):
        np.divide(np.float32(1.0), r, out=r)
        np.subtract(z32, r, out=r)
        inliers = np.less(np.abs(r, out=tmp), INLIER_M)
        # behind the plane within reach, or beyond reach in front of it: disjoint, so one count
        against = np.greater(r, BEYOND_M)
        against &= r <= REACH_M
        against |= r < -REACH_M
    score = _count_rows(inliers) - BEYOND_WEIGHT * _count_rows(against)
    score = np.where(ok, score, -np.inf)
    best = int(np.argmax(score))
    if not np.isfinite(score[best]):
        med = float(np.median(z))
        return PlaneFit(0.0, 0.0, 1.0 / med, False, 0.0)
    plane = (float(a[best]), float(b[best]), float(c[best]))
    inl = inliers[best]
    for _ in range(REFINE_ITERS):
        sol = _lstsq(u[inl], v[inl], q[inl])
        if sol is None:
            break
        inv1 = sol[0] * u + sol[1] * v + sol[2]
        if np.any(inv1 <= 1e-6):
            break
        plane = sol
        inl = np.abs(z - 1.0 / inv1) < INLIER_M
    return PlaneFit(*plane, ok=True, inlier_share=float(inl.mean()))


def height_cue(depth: np.ndarray, valid: np.ndarray) -> np.ndarray:
    """float32 [H, W]: centimetres above the dominant plane, clipped; 0 at invalid pixels."""
    fit = fit_dominant_plane(depth, valid)
    d = depth if depth.dtype == np.float32 else depth.astype(np.float32)
    with np.errstate(invalid="ignore", over="ignore"):  # invalid pixels (NaN, inf) are zeroed below
        h = np.subtract(fit.depth(depth.shape), d)  # clip((zp - d) * scale), float32, as before
        h *= np.float32(HEIGHT_SCALE)
        np.clip(h, *HEIGHT_CLIP, out=h)
    return zero_where_invalid(h, valid)


def zero_where_invalid(a: np.ndarray, valid: np.ndarray) -> np.ndarray:
    """``a`` (float32, rows contiguous) with +0.0 wherever ``valid`` is False, in place; returns ``a``.

    Why a bit mask: a masked copy (``np.copyto(..., where=valid)``) branches on every pixel and
    took 25-60 us a frame (the more ragged the mask, the more); an AND with all-ones or all-zero
    words is branch-free (~13 us) and gives the same +0.0, whatever an invalid pixel held (NaN, inf).

    Args:
        a: float32 [H, W] values, overwritten.
        valid: bool [H, W], False where ``a`` becomes 0.
    """
    m = np.asarray(valid, dtype=bool).astype(np.uint32)
    np.negative(m, out=m)  # True -> 0xFFFFFFFF, False -> 0
    bits = a.view(np.uint32)
    np.bitwise_and(bits, m, out=bits)
    return a


def _quantiles(vals: np.ndarray, qs: tuple[float, ...]) -> list[float]:
    """``np.quantile(vals, qs)`` (its default linear method, value for value) by one partition.

    Why not np.quantile: its generic path cost 3x the partition itself on a frame's ~2,400 grid
    values, and this runs on every frame at the edge.
    """
    n = len(vals)
    vi = [(n - 1) * q for q in qs]
    lo = [min(int(np.floor(x)), n - 1) for x in vi]
    hi = [min(i + 1, n - 1) for i in lo]
    part = np.partition(vals, sorted(set(lo + hi)))
    out = []
    for x, i, j in zip(vi, lo, hi):
        a, b, t = part[i], part[j], x - i
        diff = b - a
        out.append(float(b - diff * (1 - t) if t >= 0.5 else a + diff * t))  # numpy's _lerp, both branches
    return out


def robust_mean_std(depth: np.ndarray, valid: np.ndarray, std_floor: float) -> tuple[float, float]:
    """Mean and std of the valid pixels between the 1st and 99th percentile (sparse grid).

    Why: one valid pixel at 4 m, or 40 saturated 16-bit pixels (65.535 m), moved the plain
    mean/std enough to flip half of the mask (issue 9). Trimming 1 % on each side keeps the
    statistics of the scene; the grid keeps it cheap.
    """
    vals = depth[::STATS_STRIDE, ::STATS_STRIDE][valid[::STATS_STRIDE, ::STATS_STRIDE]].astype(np.float64)
    if len(vals) < MIN_POINTS:
        vals = depth[valid].astype(np.float64)
    if len(vals) == 0:
        return 0.0, 1.0
    lo, hi = _quantiles(vals, TRIM)
    core = vals[(vals >= lo) & (vals <= hi)]
    if len(core) == 0:
        core = vals
    # numpy's mean and std, operation for operation (the same pairwise sums, so the same values),
    # with the mean taken once instead of twice
    n = len(core)
    mean = float(np.add.reduce(core)) / n
    dev = np.subtract(core, mean)
    np.multiply(dev, dev, out=dev)
    return mean, max(math.sqrt(float(np.add.reduce(dev)) / n), std_floor)


STEEP_STEP = 2  # steepness: depth differences over +-2 px, averaged over 3 lines across them


def steepness_cue(depth: np.ndarray, valid: np.ndarray, intrinsics: tuple[float, float, float, float]) -> np.ndarray:
    """float32 [H, W]: 1 - cos(angle between the surface normal and the optical axis), in [0, 1].

    Why: issue 9 asks to try normals beside the height cue. One channel carries what matters of
    them here: 0 on a surface facing the camera (table, object tops), towards 1 on object sides
    and at depth jumps. The normal of the back-projected surface ``P = Z (x, y, 1)`` follows from
    the depth gradient alone (``n ~ (-fx Zu, -fy Zv, (u - cx) Zu + (v - cy) Zv + Z)``), so no
    point cloud is built. ToF noise (1-3 mm a pixel, a pixel ~1.5 mm wide at 30 cm) makes single-
    pixel differences meaningless, so Zu and Zv are differences over ``2 * STEEP_STEP`` px,
    averaged over the 3 lines across them. 0 where any pixel used is invalid, and at the border.

    Args:
        depth: [H, W] Z in metres.
        valid: [H, W] bool, pixels that returned a range.
        intrinsics: (fx, fy, cx, cy) of this frame's size (`edge.meta.SensorSpec.intrinsics_for_size`).
    """
    fx, fy, cx, cy = (np.float32(v) for v in intrinsics)
    h, w = depth.shape
    out = np.zeros((h, w), np.float32)
    k = STEEP_STEP
    if h < 2 * k + 1 or w < 2 * k + 1:
        return out
    # Invalid pixels (0, NaN, inf, beyond the range) are read as they are: every value they touch
    # is masked by ``ok``, so the result is the same as reading them as 0, one pass cheaper. The
    # arithmetic runs in place on the interior (rows and columns k .. size - k - 1), in this
    # order: export.preproc_graph repeats it operation for operation (bit-identical, tested).
    z = np.asarray(depth, dtype=np.float32)
    scale = np.float32(1.0 / (3 * 2 * k))
    rows, cols = slice(k - 1, h - k + 1), slice(k - 1, w - k + 1)
    with np.errstate(invalid="ignore", over="ignore", divide="ignore"):
        du = np.subtract(z[rows, 2 * k :], z[rows, : -2 * k])  # differences over 2k px, 3 lines
        zu = du[:-2] + du[1:-1]
        zu += du[2:]
        zu *= scale
        dv = np.subtract(z[2 * k :, cols], z[: -2 * k, cols])
        zv = dv[:, :-2] + dv[:, 1:-1]
        zv += dv[:, 2:]
        zv *= scale
        okh = valid[rows, 2 * k :] & valid[rows, : -2 * k]
        okv = valid[2 * k :, cols] & valid[: -2 * k, cols]
        ok = okh[:-2] & okh[1:-1]
        ok &= okh[2:]
        ok &= okv[:, :-2]
        ok &= okv[:, 1:-1]
        ok &= okv[:, 2:]
        ok &= valid[k : h - k, k : w - k]
        nz = (np.arange(k, w - k, dtype=np.float32) - cx) * zu  # (u - cx) Zu + (v - cy) Zv + Z
        t = (np.arange(k, h - k, dtype=np.float32)[:, None] - cy) * zv
        nz += t
        nz += z[k : h - k, k : w - k]
        zu *= fx
        zv *= fy
        zu *= zu
        zv *= zv
        zu += zv
        np.multiply(nz, nz, out=t)
        zu += t
        np.sqrt(zu, out=zu)  # |n|
        ok &= zu > 0
        np.divide(nz, zu, out=nz)  # cos
        np.clip(nz, 0.0, 1.0, out=nz)
        np.subtract(np.float32(1.0), nz, out=nz)
        np.copyto(out[k : h - k, k : w - k], nz, where=ok)
    return out
