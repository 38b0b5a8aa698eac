"""A self-contained edge model: raw depth in, object probability out, nothing else needed.

Why: a C++ robot should need only onnxruntime. The wrapper below restates `edge.preprocess`
and `edge.cues` in tensor operations (the only other place that does; the tests prove the two
agree), with a fixed frame size and no data-dependent shapes:

- invalid = not finite, <= 0 or beyond sensor.max_range_m; invalid -> 0 after standardisation;
- ``standardize="valid-pixels"``: mean and std over the valid pixels (float64 like numpy, std
  floored at ``STD_FLOOR``; no valid pixel -> mean 0, all zeros);
- ``standardize="robust"``: the valid pixels of the ``STATS_STRIDE`` grid (all valid pixels when
  fewer than ``MIN_POINTS``); their 1st and 99th percentiles exactly as ``np.quantile`` (linear):
  the needed order statistics come from a TopK of the few smallest and few largest values (the
  count of valid values only moves the gathered index), numpy's two-sided lerp in float64; mean
  and std of the values between them by masked sums; clipped to +-``ROBUST_CLIP``;
- ``cues=("height",)``: the RANSAC of `edge.cues.fit_dominant_plane` without loops: the valid
  points of the ``GRID_STRIDE`` grid are put first in row-major order by a TopK on their slot
  numbers, the fixed ``hypothesis_table`` picks ``floor(f * n)`` of them (Gather), Cramer's rule
  for all ``N_HYPOTHESES`` planes at once, masked counts for the scores, ArgMax (first max wins,
  like numpy), ``REFINE_ITERS`` unrolled least-squares refinements (3x3 normal equations by
  Cramer's rule; a failed step freezes the plane like numpy's ``break``). The fallbacks (too few
  grid points: median of all valid pixels; no usable hypothesis: median of the grid points) need
  a full sort, so they sit in an ONNX ``If`` that only runs when a frame of the batch needs it;
- ``cues=("steepness",)``: `edge.cues.steepness_cue` by slices of the frame, its float32
  operations in numpy's order; only the square root runs in float64 (torch's float32 square root
  is not correctly rounded, numpy's is; rounded back, the two agree bit for bit);
- zero-pad bottom/right to multiples of ``pad_multiple``; the network; crop; sigmoid.

Exactness: float32 steps are the same IEEE float32 operations numpy does, the hypothesis planes
and the quantiles are bit-identical; only float64 sums run in another order, and the refined
plane is solved by Cramer's rule instead of LAPACK (differences ~1e-12 relative, far below
``HEIGHT_ATOL_CM``). float32 sums are written ``x - (-y)`` (the same IEEE result) so that the
int8 quantiser, which quantises every ``Add``, leaves the preprocessing alone.

Graph I/O: input ``depth`` float32 [N, H, W] (metres, the sensor's H x W), outputs
``probability`` float32 [N, H, W] and ``valid`` bool [N, H, W] (so the caller can mark invalid
pixels unknown without recomputing it), and for a model with the height cue ``height`` float32
[N, H, W]: metres above the dominant plane the network saw (the cue channel / ``HEIGHT_SCALE``,
clipped like it, 0 at invalid pixels). Why the third: the height rule (`edge.postprocess`,
``min_height_m``) needs that plane; without it a caller would fit it a second time (``Segmenter``
did, ~0.4 ms a frame) or, in C++, reimplement the RANSAC. The frame size is fixed by the sensor
in the metadata.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
import torch
import torch.nn.functional as F
from torch import nn

from edge.cues import (
    BEYOND_M,
    BEYOND_WEIGHT,
    GRID_STRIDE,
    HEIGHT_CLIP,
    HEIGHT_SCALE,
    INLIER_M,
    MIN_POINTS,
    REACH_M,
    REFINE_ITERS,
    STATS_STRIDE,
    STEEP_STEP,
    TRIM,
    det3,
    hypothesis_table,
)
from edge.errors import ModelError, first_line
from edge.infer import INPUT_NAME, OUTPUT_HEIGHT, OUTPUT_PROB, OUTPUT_VALID, sigmoid
from edge.io import atomic_path
from edge.meta import ModelMeta
from edge.preprocess import ROBUST_CLIP, STD_FLOOR, padded_shape
from edge.train.model import FCN8s
from export.fold import folded
from export.onnx_export import OPSET, export_props, quiet_export, set_metadata, torch_logits, write_onnx

__all__ = [
    "EdgeGraph",
    "PreprocGraph",
    "edge_outputs",
    "export_with_preprocessing",
    "export_preprocessing",
    "check_supported",
    "check_against_python",
    "PROB_ATOL",
    "HEIGHT_ATOL_CM",
    "PreprocCheck",
    "SUPPORTED_STANDARDIZE",
    "SUPPORTED_CUES",
]

PROB_ATOL = 1e-4  # probability; float32 network arithmetic in two runtimes
HEIGHT_ATOL_CM = 1e-3  # height cue, when graph and numpy pick the same plane hypothesis
SUPPORTED_STANDARDIZE = ("valid-pixels", "robust")  # what PreprocGraph can express
SUPPORTED_CUES = ("height", "steepness")
NET_INPUT = "net_input"  # output name of `export_preprocessing`

_F32 = torch.float32
_F64 = torch.float64


def check_supported(meta: ModelMeta, model: nn.Module | None = None) -> None:
    """Raise a one-line `ModelError` naming what the graph cannot express for ``meta``/``model``."""
    if meta.standardize not in SUPPORTED_STANDARDIZE:
        raise ModelError(
            f"`with_preprocessing` cannot express standardize={meta.standardize!r} "
            f"(supported: {', '.join(SUPPORTED_STANDARDIZE)}); export the plain logits model instead"
        )
    bad = [c for c in meta.cues if c not in SUPPORTED_CUES]
    if bad:
        raise ModelError(
            f"`with_preprocessing` cannot compute the input cue(s) {bad} (supported: {list(SUPPORTED_CUES)}); "
            "export the plain logits model instead"
        )
    if meta.in_channels not in (1, 3):
        raise ModelError(f"`with_preprocessing` needs in_channels 1 or 3, the metadata says {meta.in_channels}")
    s = meta.sensor
    if s.height < 1 or s.width < 1:
        raise ModelError(f"`with_preprocessing` needs the sensor's frame size, the metadata says {s.height}x{s.width}")
    first = getattr(getattr(getattr(model, "encoder", None), "features", [None])[0], "in_channels", None)
    if model is not None and first is not None and first != meta.net_channels:
        raise ModelError(
            f"model's first conv takes {first} channels but its metadata says {meta.net_channels} "
            f"(in_channels {meta.in_channels} + cues {list(meta.cues)}); `with_preprocessing` cannot feed it"
        )


def _grid_slots(h: int, w: int, stride: int) -> tuple[np.ndarray, np.ndarray]:
    """(u, v) pixel coordinates of the ``[::stride, ::stride]`` grid, flattened row-major."""
    vv, uu = np.meshgrid(np.arange(0, h, stride), np.arange(0, w, stride), indexing="ij")
    return uu.ravel().astype(np.float64), vv.ravel().astype(np.float64)


def _take(x: torch.Tensor, idx: torch.Tensor) -> torch.Tensor:
    """x [N, M], idx [N, K] int64 -> [N, K]."""
    return torch.gather(x, 1, idx)


def _lerp(a: torch.Tensor, b: torch.Tensor, t: torch.Tensor) -> torch.Tensor:
    """numpy's ``_lerp`` (np.quantile, method linear), operation for operation."""
    diff = b - a
    return torch.where(t >= 0.5, b - diff * (1 - t), a + diff * t)


def _trim_k(m: int) -> int:
    """Order statistics to keep from each end so both TRIM quantiles of up to ``m`` values are exact."""
    tail = max(min(q, 1.0 - q) for q in TRIM)
    return min(m, int(np.ceil(tail * m)) + 3)


def _trimmed_mean_std(vals: torch.Tensor, ok: torch.Tensor, k: int) -> tuple[torch.Tensor, torch.Tensor]:
    """`edge.cues.robust_mean_std` after the choice of the values: vals float32 [N, M], ok bool.

    Returns float64 (mean [N], std [N]); rows without values give (0, 1).
    """
    # (python scalars, not tensor constants, here and in the other torch.cond branch functions:
    # the exporter cannot lift constants created inside a branch)
    asc = torch.topk(torch.where(ok, vals, float("inf")), k, dim=1, largest=False).values.to(_F64)  # s[0], s[1]...
    desc = torch.topk(torch.where(ok, vals, float("-inf")), k, dim=1, largest=True).values.to(_F64)  # s[n-1]...
    n = ok.sum(dim=1, keepdim=True)
    nf = n.to(_F64)
    last = torch.clamp(n - 1, min=0)

    def order_stat(i: torch.Tensor) -> torch.Tensor:  # s[i] from whichever end holds it
        from_top = last - i
        low = _take(asc, torch.clamp(i, 0, k - 1))
        high = _take(desc, torch.clamp(from_top, 0, k - 1))
        return torch.where(i < k, low, high)

    bounds = []
    for q in TRIM:
        vi = (nf - 1) * q
        prev = torch.floor(vi)
        i = torch.clamp(prev.to(torch.int64), min=0)
        bounds.append(_lerp(order_stat(i), order_stat(torch.minimum(i + 1, last)), vi - prev))
    lo, hi = bounds
    v = vals.to(_F64)
    core = ok & (v >= lo) & (v <= hi)
    cnt = core.sum(dim=1, keepdim=True)
    core = core | (ok & (cnt == 0))  # nothing between the bounds: all values (no bool Where in onnxruntime)
    cnt = torch.clamp(core.sum(dim=1, keepdim=True), min=1).to(_F64)
    mean = torch.where(core, v, 0.0).sum(dim=1, keepdim=True) / cnt
    var = torch.where(core, (v - mean) ** 2, 0.0).sum(dim=1, keepdim=True) / cnt
    std = torch.clamp(torch.sqrt(var), min=STD_FLOOR)
    empty = n[:, 0] == 0
    return torch.where(empty, 0.0, mean[:, 0]), torch.where(empty, 1.0, std[:, 0])


def _median_sorted(s: torch.Tensor, n: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """The two middle values (s[(n-1)//2], s[n//2]) of ascending rows ``s`` holding ``n`` values."""
    last = torch.clamp(n - 1, min=0)
    a = _take(s, torch.clamp(torch.div(n - 1, 2, rounding_mode="floor"), min=0)[:, None])[:, 0]
    b = _take(s, torch.minimum(torch.div(n, 2, rounding_mode="floor"), last)[:, None])[:, 0]
    return a, b


def _fallback_c(
    depth: torch.Tensor, valid: torch.Tensor, zg: torch.Tensor, gv: torch.Tensor, m: int, g: int
) -> torch.Tensor:
    """Inverse depth c of `fit_dominant_plane`'s constant fallback plane, float64 [N].

    Too few grid points: 1 / max(np.median(depth[valid]), 1e-6) (float32 median, 1 m without any
    valid pixel); otherwise (no usable hypothesis): 1 / np.median(grid depths) in float64.
    ``m`` = H * W and ``g`` = grid points, as Python ints (sizes read from a reshaped tensor are
    symbolic inside torch.cond, and the exporter then fails on a lifted constant).
    """
    flat = torch.where(valid, depth, float("inf")).reshape(depth.shape[0], -1)
    s = torch.topk(flat, m, dim=1, largest=False).values
    nv = valid.reshape(depth.shape[0], -1).sum(dim=1)
    a, b = _median_sorted(s, nv)
    med32 = (a.to(_F64) + b.to(_F64)).to(_F32) / 2  # float32 (a + b) / 2, as np.median of float32
    med32 = torch.where(nv > 0, med32, 1.0).to(_F64)
    c_few = 1.0 / torch.clamp(med32, min=1e-6)
    sg = torch.topk(torch.where(gv, zg, float("inf")), g, dim=1, largest=False).values.to(_F64)
    n = gv.sum(dim=1)
    a, b = _median_sorted(sg, n)
    c_bad = 1.0 / ((a + b) / 2)
    return torch.where(n < MIN_POINTS, c_few, c_bad)


def _no_fallback(depth: torch.Tensor, valid: torch.Tensor, zg: torch.Tensor, gv: torch.Tensor) -> torch.Tensor:
    return torch.ones_like(zg[:, 0], dtype=_F64)


def _full_frame_stats(depth: torch.Tensor, valid: torch.Tensor, k: int) -> tuple[torch.Tensor, torch.Tensor]:
    """`_trimmed_mean_std` of all pixels; ``k`` = `_trim_k` (H * W), computed before tracing (see below)."""
    nb = depth.shape[0]
    return _trimmed_mean_std(depth.reshape(nb, -1), valid.reshape(nb, -1), k)


def _no_full_frame_stats(depth: torch.Tensor, valid: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    z = torch.zeros_like(depth[:, 0, 0], dtype=_F64)
    return z, torch.ones_like(z)  # two distinct tensors: torch.cond refuses aliased outputs


class PreprocGraph(nn.Module):
    """`edge.preprocess.preprocess_for` as tensor operations: raw depth [N, H, W] -> (x [N, C, Hp, Wp], valid)."""

    def __init__(self, meta: ModelMeta) -> None:
        super().__init__()
        check_supported(meta)
        self.channels = meta.in_channels
        self.robust = meta.standardize == "robust"
        self.cues = tuple(meta.cues)
        self.h, self.w = meta.sensor.height, meta.sensor.width
        self.intrinsics = meta.sensor.intrinsics_for_size(self.h, self.w)
        self.max_range = float(np.float32(meta.sensor.max_range_m))  # edge.preprocess.valid_for: no return beyond the range
        self.hp, self.wp = padded_shape(self.h, self.w, meta.pad_multiple)
        u, v = _grid_slots(self.h, self.w, GRID_STRIDE)
        self.g = len(u)
        # Python ints fixed here: sizes read from tensors are symbolic inside torch.cond, and numpy
        # called while tracing a branch leaves a constant the exporter cannot lift
        self.k_stats = _trim_k(len(range(0, self.h, STATS_STRIDE)) * len(range(0, self.w, STATS_STRIDE)))
        self.k_full = _trim_k(self.h * self.w)
        self.register_buffer("u64", torch.from_numpy(u), persistent=False)
        self.register_buffer("v64", torch.from_numpy(v), persistent=False)
        self.register_buffer("u32", torch.from_numpy(u.astype(np.float32)), persistent=False)
        self.register_buffer("v32", torch.from_numpy(v.astype(np.float32)), persistent=False)
        self.register_buffer("slot", torch.arange(self.g, dtype=_F32), persistent=False)
        self.register_buffer("frac", torch.from_numpy(np.asarray(hypothesis_table(), np.float64)), persistent=False)
        self.register_buffer("cols", torch.arange(self.w, dtype=_F32)[None, None, :], persistent=False)
        self.register_buffer("rows", torch.arange(self.h, dtype=_F32)[None, :, None], persistent=False)

    # -- standardisation ---------------------------------------------------------------------
    def _plain_stats(self, d: torch.Tensor, valid: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        v = valid.to(_F64)
        n = torch.clamp(v.sum(dim=(1, 2), keepdim=True), min=1.0)
        mean = d.sum(dim=(1, 2), keepdim=True) / n
        var = (((d - mean) * v) ** 2).sum(dim=(1, 2), keepdim=True) / n
        return mean, torch.clamp(torch.sqrt(var), min=STD_FLOOR)

    def _robust_stats(self, depth: torch.Tensor, valid: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        s = STATS_STRIDE
        vals = depth[:, ::s, ::s].reshape(depth.shape[0], -1)
        ok = valid[:, ::s, ::s].reshape(depth.shape[0], -1)
        mean, std = _trimmed_mean_std(vals, ok, self.k_stats)
        few = ok.sum(dim=1) < MIN_POINTS
        k = self.k_full

        def full(depth: torch.Tensor, valid: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
            return _full_frame_stats(depth, valid, k)

        fmean, fstd = torch.cond(few.any(), full, _no_full_frame_stats, (depth, valid))
        mean, std = torch.where(few, fmean, mean), torch.where(few, fstd, std)
        return mean[:, None, None], std[:, None, None]

    # -- height cue --------------------------------------------------------------------------
    def _lstsq(self, inl: torch.Tensor, q: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]:
        """Least-squares plane through the inliers: normal equations by Cramer's rule; (a, b, c, ok)."""
        zero = torch.zeros((), dtype=_F64)
        u, v = self.u64, self.v64

        def msum(x: torch.Tensor) -> torch.Tensor:
            return torch.where(inl, x, zero).sum(dim=1)

        su, sv, n = msum(u), msum(v), msum(torch.ones_like(q))
        suu, suv, svv = msum(u * u), msum(u * v), msum(v * v)
        suq, svq, sq = msum(u * q), msum(v * q), msum(q)

        det = det3(suu, suv, su, suv, svv, sv, su, sv, n)
        ok = (n >= 3) & (torch.abs(det) >= 1e-9)
        d = torch.where(ok, det, torch.ones((), dtype=_F64))
        a = det3(suq, suv, su, svq, svv, sv, sq, sv, n) / d
        b = det3(suu, suq, su, suv, svq, sv, su, sq, n) / d
        c = det3(suu, suv, suq, suv, svv, svq, su, sv, sq) / d
        return a, b, c, ok

    def _height(self, depth: torch.Tensor, valid: torch.Tensor) -> torch.Tensor:
        nb = depth.shape[0]
        s = GRID_STRIDE
        one32 = torch.ones((), dtype=_F32)
        gv = valid[:, ::s, ::s].reshape(nb, -1)
        zg32 = torch.where(gv, depth[:, ::s, ::s].reshape(nb, -1), one32)
        z = zg32.to(_F64)
        q = 1.0 / z
        n = gv.sum(dim=1)  # valid grid points
        # valid points first, in row-major order: point k of the table is order[k]
        order = torch.topk(torch.where(gv, self.slot, self.slot + self.g), self.g, dim=1, largest=False).indices
        idx = torch.floor(self.frac[None] * n.to(_F64)[:, None, None]).to(torch.int64)  # [N, K, 3]
        idx = torch.clamp(torch.minimum(idx, (n - 1)[:, None, None]), min=0)
        pos = _take(order, idx.reshape(nb, -1))
        uh, vh, qh = self.u64[pos], self.v64[pos], _take(q, pos)
        kk = idx.shape[1]
        u1, u2, u3 = uh.reshape(nb, kk, 3).unbind(-1)
        v1, v2, v3 = vh.reshape(nb, kk, 3).unbind(-1)
        q1, q2, q3 = qh.reshape(nb, kk, 3).unbind(-1)
        # edge.cues._solve3, term for term
        det = u1 * (v2 - v3) - v1 * (u2 - u3) + (u2 * v3 - u3 * v2)
        ok = torch.abs(det) > 1.0
        dd = torch.where(ok, det, torch.ones((), dtype=_F64))
        a = (q1 * (v2 - v3) - v1 * (q2 - q3) + (q2 * v3 - q3 * v2)) / dd
        b = (u1 * (q2 - q3) - q1 * (u2 - u3) + (u2 * q3 - u3 * q2)) / dd
        c = (u1 * (v2 * q3 - v3 * q2) - v1 * (u2 * q3 - u3 * q2) + q1 * (u2 * v3 - u3 * v2)) / dd
        # scores in float32 like numpy: inv = (a u + b v) + c, written x - (-y) (see module docstring)
        a32, b32, c32 = a.to(_F32)[..., None], b.to(_F32)[..., None], c.to(_F32)[..., None]
        inv = (a32 * self.u32 - (-(b32 * self.v32))) - (-c32)  # [N, K, G]
        g3 = gv[:, None, :]
        eps32 = torch.tensor(1e-6, dtype=_F32)
        # numpy: inv.min() > 1e-6 over the valid points; counts as float32 sums (exact below 2^24)
        ok = ok & ((g3 & (inv <= eps32)).to(_F32).sum(dim=2) == 0)
        r = zg32[:, None, :] - 1.0 / torch.maximum(inv, eps32)
        inl = g3 & (torch.abs(r) < torch.tensor(INLIER_M, dtype=_F32))
        reach = torch.tensor(REACH_M, dtype=_F32)
        beyond = g3 & (r > torch.tensor(BEYOND_M, dtype=_F32)) & (r <= reach)
        front = g3 & (r < -reach)
        # numpy adds the two integer counts before weighting them: so does the graph (exact in float32)
        against = (beyond.to(_F32).sum(dim=2) + front.to(_F32).sum(dim=2)).to(_F64)
        score = inl.to(_F32).sum(dim=2).to(_F64) - BEYOND_WEIGHT * against
        score = torch.where(ok, score, torch.tensor(float("-inf"), dtype=_F64))
        best = torch.argmax(score, dim=1, keepdim=True)  # first max wins, like numpy
        found = ok.any(dim=1) & (n >= MIN_POINTS)
        pa, pb, pc = _take(a, best)[:, 0], _take(b, best)[:, 0], _take(c, best)[:, 0]
        cur = torch.gather(inl, 1, best[:, :, None].expand(nb, 1, self.g))[:, 0]  # [N, G]
        going = found
        for _ in range(REFINE_ITERS):  # unrolled; a failed step stops the refinement (numpy: break)
            sa, sb, sc, sok = self._lstsq(cur, q)
            inv1 = sa[:, None] * self.u64 + sb[:, None] * self.v64 + sc[:, None]
            sok = sok & ~(gv & (inv1 <= 1e-6)).any(dim=1)
            going = going & sok
            pa, pb, pc = torch.where(going, sa, pa), torch.where(going, sb, pb), torch.where(going, sc, pc)
            new = gv & (torch.abs(z - 1.0 / inv1) < INLIER_M)
            cur = (going[:, None] & new) | (~going[:, None] & cur)  # onnxruntime has no bool Where
        need = ~found
        m, g = self.h * self.w, self.g

        def fallback(depth: torch.Tensor, valid: torch.Tensor, zg: torch.Tensor, gv: torch.Tensor) -> torch.Tensor:
            return _fallback_c(depth, valid, zg, gv, m, g)

        cfb = torch.cond(need.any(), fallback, _no_fallback, (depth, valid, zg32, gv))
        zero = torch.zeros((), dtype=_F64)
        pa, pb, pc = torch.where(need, zero, pa), torch.where(need, zero, pb), torch.where(need, cfb, pc)
        # PlaneFit.depth and height_cue, float32
        pa32, pb32, pc32 = pa.to(_F32)[:, None, None], pb.to(_F32)[:, None, None], pc.to(_F32)[:, None, None]
        invp = (pa32 * self.cols - (-(pb32 * self.rows))) - (-pc32)
        zp = 1.0 / torch.maximum(invp, eps32)
        d = torch.where(valid, depth, zp)
        return torch.clamp((zp - d) * torch.tensor(HEIGHT_SCALE, dtype=_F32), *HEIGHT_CLIP)

    # -- steepness cue -------------------------------------------------------------------------
    def _steepness(self, depth: torch.Tensor, valid: torch.Tensor) -> torch.Tensor:
        """`edge.cues.steepness_cue` for a batch, the same float32 operations in the same order."""
        h, w, k = self.h, self.w, STEEP_STEP
        fx, fy, cx, cy = (torch.tensor(float(np.float32(v)), dtype=_F32) for v in self.intrinsics)
        z = torch.where(valid, depth, torch.zeros_like(depth))
        scale = torch.tensor(float(np.float32(1.0 / (3 * 2 * k))), dtype=_F32)
        du = z[:, :, 2 * k :] - z[:, :, : -2 * k]
        zu = ((du[:, :-2] - (-du[:, 1:-1])) - (-du[:, 2:])) * scale  # a + b written a - (-b): see the module docstring
        dv = z[:, 2 * k :] - z[:, : -2 * k]
        zv = ((dv[:, :, :-2] - (-dv[:, :, 1:-1])) - (-dv[:, :, 2:])) * scale
        okh = valid[:, :, 2 * k :] & valid[:, :, : -2 * k]
        okv = valid[:, 2 * k :] & valid[:, : -2 * k]
        zu = zu[:, k - 1 : h - k - 1]
        zv = zv[:, :, k - 1 : w - k - 1]
        ok = (okh[:, :-2] & okh[:, 1:-1] & okh[:, 2:])[:, k - 1 : h - k - 1]
        ok = ok & (okv[:, :, :-2] & okv[:, :, 1:-1] & okv[:, :, 2:])[:, :, k - 1 : w - k - 1]
        zc = z[:, k : h - k, k : w - k]
        ok = ok & valid[:, k : h - k, k : w - k]
        uu = self.cols[:, :, k : w - k] - cx
        vv = self.rows[:, k : h - k] - cy
        nz = ((uu * zu) - (-(vv * zv))) - (-zc)
        gu, gv = fx * zu, fy * zv
        # float32 sqrt in torch is not correctly rounded (numpy's is); through float64 it is, in both runtimes
        norm = torch.sqrt((((gu * gu) - (-(gv * gv))) - (-(nz * nz))).to(_F64)).to(_F32)
        one = torch.ones((), dtype=_F32)
        cos = torch.where(ok & (norm > 0), nz / torch.where(norm > 0, norm, one), one)
        inner = torch.where(ok, one - torch.clamp(cos, 0.0, 1.0), torch.zeros((), dtype=_F32))
        return F.pad(inner, (k, k, k, k))

    def forward(self, depth: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        planes, valid = self.planes(depth)
        return self.assemble(planes), valid

    def assemble(self, planes: list[torch.Tensor]) -> torch.Tensor:
        """The network input [N, C, Hp, Wp] from `planes`' channels (zero padding bottom/right)."""
        x = torch.stack(planes, dim=1) if len(planes) > 1 else planes[0].unsqueeze(1)
        return F.pad(x, (0, self.wp - self.w, 0, self.hp - self.h))

    def planes(self, depth: torch.Tensor) -> tuple[list[torch.Tensor], torch.Tensor]:
        """The input channels [N, H, W] each (depth copies, then the cues in ``meta.cues`` order), and valid."""
        valid = torch.isfinite(depth) & (depth > 0) & (depth <= self.max_range)
        d = torch.where(valid, depth, torch.zeros_like(depth)).to(_F64)
        if self.robust:
            mean, std = self._robust_stats(depth, valid)
            z = torch.clamp((d - mean) / std, -ROBUST_CLIP, ROBUST_CLIP)
        else:
            mean, std = self._plain_stats(d, valid)
            z = (d - mean) / std
        z = torch.where(valid, z, torch.zeros_like(d)).to(_F32)
        planes = [z] * self.channels
        for cue in self.cues:
            if cue == "height":
                planes.append(self._height(depth, valid))
            elif cue == "steepness":
                planes.append(self._steepness(depth, valid))
        return planes, valid


def edge_outputs(meta: ModelMeta) -> list[str]:
    """The output names of `EdgeGraph` for ``meta``: probability, valid, and height with the height cue."""
    return [OUTPUT_PROB, OUTPUT_VALID] + ([OUTPUT_HEIGHT] if "height" in meta.cues else [])


class EdgeGraph(nn.Module):
    """`PreprocGraph` + FCN-8s + crop + sigmoid as one module (see the module docstring)."""

    def __init__(self, model: FCN8s, meta: ModelMeta) -> None:
        super().__init__()
        check_supported(meta, model)
        self.pre = PreprocGraph(meta)
        self.model = folded(model.eval())  # the affine head as two matrix products (export.fold)
        self.h, self.w = meta.sensor.height, meta.sensor.width
        # the height cue's channel in the network input, None without the cue
        self.height_ch = meta.in_channels + meta.cues.index("height") if "height" in meta.cues else None

    def forward(self, depth: torch.Tensor) -> tuple[torch.Tensor, ...]:
        planes, valid = self.pre.planes(depth)
        logits = self.model(self.pre.assemble(planes))[:, 0, : self.h, : self.w]
        if self.height_ch is None:
            return torch.sigmoid(logits), valid
        # metres, as edge.postprocess.support_height: the same float32 division of the same cue.
        # Taken from the cue itself, not from the assembled input, which --int8 quantises.
        return torch.sigmoid(logits), valid, planes[self.height_ch] / HEIGHT_SCALE


def _export(module: nn.Module, meta: ModelMeta, out: str | Path, output_names: list[str]):
    """Dynamo-export ``module`` (raw depth [N, H, W] in, dynamic batch) and return the ONNX proto."""
    import onnx

    # two example frames: with one, torch.export specialises the batch to 1 inside torch.cond
    example = torch.full((2, meta.sensor.height, meta.sensor.width), 0.3)
    raw = atomic_path(Path(out)).with_suffix(".raw.onnx")
    try:
        with quiet_export(), torch.no_grad():
            torch.onnx.export(
                module.eval(),
                (example,),
                str(raw),
                input_names=[INPUT_NAME],
                output_names=output_names,
                opset_version=OPSET,
                dynamo=True,
                external_data=False,
                dynamic_shapes=({0: torch.export.Dim("batch", min=1, max=1024)},),
                optimize=True,
            )
        return onnx.load(str(raw), load_external_data=False)
    except Exception as exc:  # noqa: BLE001 - exporter failures come in many types
        raise ModelError(f"torch.onnx.export failed ({type(exc).__name__}: {first_line(exc, 200)})") from None
    finally:
        raw.unlink(missing_ok=True)
        Path(str(raw) + ".data").unlink(missing_ok=True)


def export_with_preprocessing(
    model: FCN8s, meta: ModelMeta, out: str | Path, extra_props: dict[str, str] | None = None
) -> Path:
    """Export `EdgeGraph` to one self-contained file with the model's metadata.

    Raises a one-line `ModelError` when the graph cannot express the model's preprocessing
    (`check_supported`) or the exporter fails.
    """
    names = edge_outputs(meta)
    proto = _export(EdgeGraph(model, meta), meta, out, names)
    s = meta.sensor
    proto.doc_string = (
        f"depthseg edge model: raw depth [N,{s.height},{s.width}] metres (0/NaN/neg/inf invalid) -> "
        + ", ".join(f"{n} [N,{s.height},{s.width}]" for n in names)
    )
    props = {"graph": "with-preprocessing", "preprocessing_graph": f"standardize={meta.standardize}; cues={list(meta.cues)}"}
    set_metadata(proto, export_props(meta, props | (extra_props or {})))
    return write_onnx(proto, out)


def export_preprocessing(meta: ModelMeta, out: str | Path) -> Path:
    """The preprocessing alone (`PreprocGraph`): depth [N, H, W] -> net_input [N, C, Hp, Wp], valid.

    For checking the graph's network input against `edge.preprocess` and for debugging on the
    robot (what the network saw); not a model file the `Segmenter` loads.
    """
    proto = _export(PreprocGraph(meta), meta, out, [NET_INPUT, OUTPUT_VALID])
    proto.doc_string = f"depthseg preprocessing only (standardize={meta.standardize}, cues={list(meta.cues)})"
    set_metadata(proto, export_props(meta, {"graph": "preprocessing-only"}))
    return write_onnx(proto, out)


@dataclass(frozen=True)
class PreprocCheck:
    """Outcome of comparing a --with-preprocessing file with the Python path on the same frames.

    ``max_abs_height_diff_m``: the graph's ``height`` output against `edge.postprocess.support_height`
    (None for a graph without that output); ``height_tolerance_m`` is ``HEIGHT_ATOL_CM`` in metres.
    """

    frames: int
    source: str
    max_abs_prob_diff: float
    tolerance: float
    valid_mismatch: int
    flip_fraction: float
    max_abs_height_diff_m: float | None = None
    height_tolerance_m: float = HEIGHT_ATOL_CM / HEIGHT_SCALE

    @property
    def ok(self) -> bool:
        height_ok = self.max_abs_height_diff_m is None or self.max_abs_height_diff_m <= self.height_tolerance_m
        return self.max_abs_prob_diff <= self.tolerance and self.valid_mismatch == 0 and height_ok

    def to_dict(self) -> dict:
        return asdict(self) | {"ok": self.ok}

    def summary(self) -> str:
        height = (
            "" if self.max_abs_height_diff_m is None
            else f", max |height diff| {self.max_abs_height_diff_m:.2e} m (tolerance {self.height_tolerance_m:.0e})"
        )
        return (
            f"check vs the Python path (edge.preprocess + PyTorch) on {self.source}: max |prob diff| "
            f"{self.max_abs_prob_diff:.2e} (tolerance {self.tolerance:.0e}), valid-mask mismatches {self.valid_mismatch}, "
            f"mask flips {100 * self.flip_fraction:.4f} % of valid pixels{height}"
        )


def check_against_python(
    onnx_path: str | Path, model: FCN8s, meta: ModelMeta, frames: list[np.ndarray], source: str = "", threads: int = 2
) -> PreprocCheck:
    """Run the self-contained file through `Segmenter` and compare with the Python path; raise above tolerance."""
    from edge.infer import Segmenter
    from edge.postprocess import support_height
    from edge.preprocess import valid_for

    seg = Segmenter(onnx_path, threads=threads)
    has_height = seg.has_height_output
    worst, mism, flips, n_valid, worst_h = 0.0, 0, 0, 0, 0.0
    for d in frames:
        pred = seg.predict(d)
        ref_p = sigmoid(torch_logits(model, meta, d))
        ref_v = valid_for(d, meta)
        worst = max(worst, float(np.max(np.abs(pred.prob - ref_p))))
        mism += int(np.count_nonzero(pred.valid != ref_v))
        flips += int(np.count_nonzero(((pred.prob >= seg.threshold) != (ref_p >= seg.threshold)) & ref_v))
        n_valid += int(ref_v.sum())
        if has_height:
            worst_h = max(worst_h, float(np.max(np.abs(seg.graph_height(d) - support_height(d, ref_v)))))
    check = PreprocCheck(
        frames=len(frames),
        source=source or f"{len(frames)} frames",
        max_abs_prob_diff=worst,
        tolerance=PROB_ATOL,
        valid_mismatch=mism,
        flip_fraction=flips / max(n_valid, 1),
        max_abs_height_diff_m=worst_h if has_height else None,
    )
    if not check.ok:
        raise ModelError(f"{onnx_path}: self-contained graph differs from the Python path: {check.summary()}")
    return check
