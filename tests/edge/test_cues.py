"""Height cue and robust standardisation (edge.cues): geometry, robustness, determinism."""

from __future__ import annotations

import numpy as np
import pytest

from edge.cues import (
    BEYOND_M,
    BEYOND_WEIGHT,
    HEIGHT_CLIP,
    INLIER_M,
    MIN_POINTS,
    REACH_M,
    REFINE_ITERS,
    STATS_STRIDE,
    TRIM,
    PlaneFit,
    _grid,
    _quantiles,
    _solve3,
    fit_dominant_plane,
    height_cue,
    hypothesis_table,
    robust_mean_std,
    steepness_cue,
    zero_where_invalid,
)
from edge.meta import ModelMeta
from edge.preprocess import ROBUST_CLIP, preprocess, preprocess_for, standardize, valid_mask

H, W = 171, 224
FX, FY, CX, CY = 202.0, 204.8, 115.8, 88.0


def _tilted_floor(dist: float = 0.3, tilt: tuple[float, float] = (0.12, -0.08)) -> np.ndarray:
    """Z of the plane n . X = d seen by a pinhole camera (n tilted away from the optical axis)."""
    v, u = np.mgrid[0:H, 0:W].astype(np.float64)
    xn, yn = (u - CX) / FX, (v - CY) / FY
    n = np.array([np.sin(tilt[0]), np.sin(tilt[1]), 1.0])
    n /= np.linalg.norm(n)
    return (dist / (n[0] * xn + n[1] * yn + n[2])).astype(np.float32)


def _scene(rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    z = _tilted_floor()
    label = np.zeros((H, W), np.uint8)
    for _ in range(6):
        r0, c0 = rng.integers(10, H - 40), rng.integers(10, W - 40)
        hh, ww = rng.integers(10, 30, size=2)
        z[r0 : r0 + hh, c0 : c0 + ww] -= rng.uniform(0.02, 0.08)
        label[r0 : r0 + hh, c0 : c0 + ww] = 1
    z += rng.normal(0, 0.002, z.shape).astype(np.float32)
    z[:12, :12] = 0  # a dead corner
    z[rng.random(z.shape) < 0.002] = np.nan
    return z, label


def test_plane_fit_recovers_a_tilted_floor_without_intrinsics() -> None:
    z = _tilted_floor()
    fit = fit_dominant_plane(z, valid_mask(z))
    assert fit.ok and fit.inlier_share > 0.99
    np.testing.assert_allclose(fit.depth(z.shape), z, rtol=1e-5)


def test_height_cue_is_object_height_in_cm_and_zero_where_invalid() -> None:
    z, label = _scene(np.random.default_rng(0))
    valid = valid_mask(z)
    h = height_cue(z, valid)
    assert h.dtype == np.float32 and h.shape == z.shape
    assert np.all(h[~valid] == 0)
    floor = valid & (label == 0)
    assert np.abs(np.median(h[floor])) < 0.05 and np.percentile(np.abs(h[floor]), 95) < 0.8
    assert np.median(h[valid & (label == 1)]) > 1.5
    # height alone separates this easy scene almost perfectly: the cue carries the geometry
    pred = (h > 0.8) & valid
    gt = (label == 1) & valid
    assert (pred & gt).sum() / (pred | gt).sum() > 0.95


def test_box_top_bigger_than_the_visible_floor_does_not_become_the_plane() -> None:
    """A support surface has nothing behind it: the floor wins over a large box top."""
    z = _tilted_floor()
    z[20:150, 30:200] -= 0.05  # box top covering ~58 % of the frame
    h = height_cue(z, valid_mask(z))
    assert np.median(h[20:150, 30:200]) == pytest.approx(5.0, abs=0.6)
    assert np.abs(np.median(h[:15, :])) < 0.1


def test_table_edge_with_more_floor_than_free_table_keeps_the_table_as_the_plane() -> None:
    """Nothing stands 30 cm above a support seen from 20-40 cm: a far floor past a table edge,
    which everything else in view stands in front of, loses to the table (docs/worst, frame 703)."""
    z = _tilted_floor(dist=0.35)
    rows, cols = np.mgrid[0:H, 0:W]
    floor = rows < 0.8 * cols  # 52 % of the frame: the floor past the edge, 45 cm lower
    z[floor] += 0.45
    z[110:165, 10:130] -= 0.06  # objects on the table, 17 %: 30 % free table, less than the floor
    free = ~floor
    free[110:165, 10:130] = False
    assert floor.sum() > free.sum()
    h = height_cue(z, valid_mask(z))
    assert np.abs(np.median(h[free])) < 0.1
    assert np.median(h[110:165, 10:130]) == pytest.approx(6.0, abs=0.6)
    assert np.all(h[floor] == HEIGHT_CLIP[0])  # the floor reads as far below as the cue goes


def test_height_cue_is_deterministic_and_clipped() -> None:
    z, _ = _scene(np.random.default_rng(1))
    z[50, 50] = 4.0  # far below the table: clipped, not propagated
    a, b = height_cue(z, valid_mask(z)), height_cue(z.copy(), valid_mask(z))
    assert np.array_equal(a, b)
    assert a.min() >= HEIGHT_CLIP[0] and a.max() <= HEIGHT_CLIP[1]
    assert a[50, 50] == HEIGHT_CLIP[0]


def test_height_cue_falls_back_on_an_almost_empty_frame() -> None:
    z = np.zeros((H, W), np.float32)
    z[80:83, 100:103] = 0.3
    h = height_cue(z, valid_mask(z))
    assert np.all(np.isfinite(h)) and np.all(h[z == 0] == 0)
    assert np.all(height_cue(np.zeros((H, W), np.float32), np.zeros((H, W), bool)) == 0)


@pytest.mark.parametrize("outlier", ["one pixel at 4 m", "40 pixels at 65.535 m"])
def test_robust_standardisation_ignores_a_few_far_or_saturated_pixels(outlier: str) -> None:
    z, _ = _scene(np.random.default_rng(2))
    bad = z.copy()
    if outlier.startswith("one"):
        bad[100, 120] = 4.0
    else:
        idx = np.random.default_rng(3).choice(H * W, 40, replace=False)
        bad.ravel()[idx] = 65.535
    plain, _, _ = standardize(z, mode="valid-pixels")
    plain_bad, _, _ = standardize(bad, mode="valid-pixels")
    rob, m0, s0 = standardize(z, mode="robust")
    rob_bad, m1, s1 = standardize(bad, mode="robust")
    keep = valid_mask(z) & (bad == z)
    # the plain statistics move the whole frame; the robust ones do not
    assert np.median(np.abs(plain_bad[keep] - plain[keep])) > 0.1
    assert np.max(np.abs(rob_bad[keep] - rob[keep])) < 0.05
    assert abs(m1 - m0) < 1e-3 and abs(s1 / s0 - 1) < 0.05
    assert np.abs(rob_bad).max() <= ROBUST_CLIP


def test_robust_mean_std_of_a_constant_frame_uses_the_floor() -> None:
    z = np.full((H, W), 0.3, np.float32)
    mean, std = robust_mean_std(z, valid_mask(z), 1e-6)
    assert mean == pytest.approx(0.3) and std == 1e-6


def test_preprocess_adds_cue_channels_after_the_depth_copies() -> None:
    z, _ = _scene(np.random.default_rng(4))
    meta = ModelMeta(in_channels=3, standardize="robust", cues=("height",))
    p = preprocess_for(z, meta)
    assert p.x.shape == (4, 192, 224) and meta.net_channels == 4
    assert np.array_equal(p.x[0], p.x[2])
    np.testing.assert_array_equal(p.x[3, :H, :W], height_cue(z, valid_mask(z)))
    assert not p.x[:, H:, :].any()
    with pytest.raises(Exception, match="unknown input cue"):
        preprocess(z, 1, cues=("normals",))


def test_quantiles_are_numpys_value_for_value() -> None:
    # the edge path replaces np.quantile by one partition; the trimming bounds must not move
    rng = np.random.default_rng(7)
    for n in (1, 2, 3, 57, 1000, 2431):
        for vals in (rng.random(n), np.round(rng.random(n), 2), rng.normal(0.3, 0.01, n)):
            assert _quantiles(vals, TRIM) == list(np.quantile(vals, TRIM))


def test_height_cue_equals_the_plain_expression() -> None:
    # the in-place arithmetic of height_cue and PlaneFit.depth gives the plain formula's float32 values
    z, _ = _scene(np.random.default_rng(5))
    z[40:44, 50:60] = 65.535  # saturated pixels, as read by a model without a range rule
    valid = valid_mask(z)
    fit = fit_dominant_plane(z, valid)
    ar_u, ar_v = np.arange(W, dtype=np.float32), np.arange(H, dtype=np.float32)
    inv = (np.float32(fit.a) * ar_u[None, :] + np.float32(fit.b) * ar_v[:, None]) + np.float32(fit.c)
    zp = 1.0 / np.maximum(inv, np.float32(1e-6))
    d = np.where(valid, z, zp).astype(np.float32)
    plain = np.clip((zp - d) * np.float32(100.0), *HEIGHT_CLIP).astype(np.float32)
    np.testing.assert_array_equal(fit.depth((H, W)), zp)
    np.testing.assert_array_equal(height_cue(z, valid), plain)


def test_steepness_of_a_tilted_plane_is_one_minus_the_cosine_of_its_tilt() -> None:
    z = _tilted_floor()
    c = steepness_cue(z, valid_mask(z), (FX, FY, CX, CY))
    n = np.array([np.sin(0.12), np.sin(-0.08), 1.0])
    expected = 1.0 - n[2] / np.linalg.norm(n)
    np.testing.assert_allclose(c[2:-2, 2:-2], expected, atol=2e-6)
    assert not c[:2].any() and not c[-2:].any() and not c[:, :2].any() and not c[:, -2:].any()  # border


def test_steepness_is_high_at_object_sides_and_zero_near_invalid_pixels() -> None:
    z = np.full((H, W), 0.3, np.float32)
    z[60:120, 80:160] = 0.24  # a 6 cm box: its top faces the camera, its outline is a depth jump
    z[10, 10] = 0.0  # a dead pixel
    c = steepness_cue(z, valid_mask(z), (FX, FY, CX, CY))
    assert c.dtype == np.float32 and c.shape == (H, W)
    assert c[90, 120] == 0 and c[30, 40] == 0  # the top and the table face the camera
    assert c[60, 120] > 0.7 and c[90, 80] > 0.7  # the box's outline: a 6 cm jump within 4 px
    assert np.all(c[8:13, 8:13] == 0)  # every value whose differences read the dead pixel
    assert c.min() >= 0 and c.max() <= 1


def test_steepness_needs_the_sensor_and_rides_in_input_options() -> None:
    z, _ = _scene(np.random.default_rng(6))
    meta = ModelMeta(in_channels=1, standardize="robust", cues=("height", "steepness"))
    p = preprocess_for(z, meta)
    assert p.x.shape == (3, 192, 224)
    np.testing.assert_array_equal(p.x[2, :H, :W], steepness_cue(z, valid_mask(z), meta.sensor.intrinsics_for_size(H, W)))
    with pytest.raises(Exception, match="needs the camera's intrinsics"):
        preprocess(z, 1, cues=("steepness",))


def _plain_plane_fit(depth: np.ndarray, valid: np.ndarray, stride: int = 6) -> tuple[float, float, float, bool, float]:
    """The plane fit's rule written plainly (the clamp, three counts, LAPACK's determinant), as before 2026-12-08."""
    vv, uu = np.nonzero(valid[::stride, ::stride])
    z = depth[::stride, ::stride][vv, uu].astype(np.float64)
    u, v = uu.astype(np.float64) * stride, vv.astype(np.float64) * stride
    n = len(z)
    assert n >= MIN_POINTS
    q = 1.0 / z
    idx = np.minimum((hypothesis_table() * n).astype(np.int64), n - 1)
    a, b, c, ok = _solve3(u[idx], v[idx], q[idx])
    inv = (a.astype(np.float32)[:, None] * u.astype(np.float32) + b.astype(np.float32)[:, None] * v.astype(np.float32)) \
        + c.astype(np.float32)[:, None]
    ok &= inv.min(axis=1) > 1e-6
    r = z.astype(np.float32) - np.float32(1.0) / np.maximum(inv, np.float32(1e-6))
    score = (np.count_nonzero(np.abs(r) < INLIER_M, axis=1)
             - BEYOND_WEIGHT * (np.count_nonzero((r > BEYOND_M) & (r <= REACH_M), axis=1)
                                + np.count_nonzero(r < -REACH_M, axis=1)))
    best = int(np.argmax(np.where(ok, score, -np.inf)))
    plane = (float(a[best]), float(b[best]), float(c[best]))
    inl = np.abs(r[best]) < INLIER_M
    for _ in range(REFINE_ITERS):
        uu_, vv_, qq_ = u[inl], v[inl], q[inl]
        ata = np.array([[uu_ @ uu_, uu_ @ vv_, uu_.sum()], [uu_ @ vv_, vv_ @ vv_, vv_.sum()],
                        [uu_.sum(), vv_.sum(), float(len(uu_))]])
        if len(qq_) < 3 or abs(np.linalg.det(ata)) < 1e-9:
            break
        sol = np.linalg.solve(ata, np.array([uu_ @ qq_, vv_ @ qq_, qq_.sum()]))
        inv1 = sol[0] * u + sol[1] * v + sol[2]
        if np.any(inv1 <= 1e-6):
            break
        plane = (float(sol[0]), float(sol[1]), float(sol[2]))
        inl = np.abs(z - 1.0 / inv1) < INLIER_M
    return (*plane, True, float(inl.mean()))


def test_plane_fit_equals_its_plain_rule_value_for_value() -> None:
    # the edge path skips the clamp of hypotheses that are not ok, counts in 16-bit lanes and
    # merges the two against-counts: none of it may move the plane
    rng = np.random.default_rng(11)
    behind = 0
    for k in range(12):
        z, _ = _scene(rng)
        if k % 3 == 1:
            z[:, 100:] += 0.35  # past a table edge: the floor, 35 cm lower, more of the view than the table
        if k % 3 == 2:
            z[30:60, 40:200] -= 0.25  # a box top the size of a third of the view
        valid = valid_mask(z)
        fit = fit_dominant_plane(z, valid)
        assert (fit.a, fit.b, fit.c, fit.ok, fit.inlier_share) == _plain_plane_fit(z, valid)
        u, v, g = _grid(z, valid, 6)
        i = np.minimum((hypothesis_table() * len(g)).astype(np.int64), len(g) - 1)
        a, b, c, _ok = _solve3(u[i], v[i], 1.0 / g[i])
        behind += int(np.sum((a[:, None] * u + b[:, None] * v + c[:, None]).min(axis=1) <= 1e-6))
    assert behind > 0  # some hypotheses had a point at or behind the camera: the skipped clamp was exercised


def test_plane_depth_clamps_a_plane_that_crosses_behind_the_camera() -> None:
    for a, b, c in ((-0.02, 0.0, 1.5), (0.0, -0.03, 2.0), (0.01, 0.002, 3.0), (0.0, 0.0, 1e-9)):
        inv = (np.float32(a) * np.arange(W, dtype=np.float32)[None, :] + np.float32(b) * np.arange(H, dtype=np.float32)[:, None]) \
            + np.float32(c)
        plain = np.float32(1.0) / np.maximum(inv, np.float32(1e-6))
        np.testing.assert_array_equal(PlaneFit(a, b, c, True, 1.0).depth((H, W)), plain)


def test_zero_where_invalid_writes_positive_zeros_and_keeps_the_rest() -> None:
    a = np.array([[1.5, np.nan, -np.inf, -2.0], [np.inf, 0.25, -0.0, 7.0]], np.float32)
    valid = np.array([[True, False, False, True], [False, True, False, True]])
    out = zero_where_invalid(a.copy(), valid)
    assert np.array_equal(out[valid], a[valid])
    assert np.all(out[~valid].view(np.uint32) == 0)  # +0.0 bit for bit, whatever the pixel held


def test_robust_statistics_are_numpys_mean_and_std() -> None:
    rng = np.random.default_rng(2)
    for n in (12, 13, 400, 2289, 6000):
        for dtype in (np.float32, np.float64):
            d = (rng.normal(0.3, 0.05, (1, n * STATS_STRIDE))).astype(dtype)
            valid = np.ones_like(d, dtype=bool)
            vals = d[::STATS_STRIDE, ::STATS_STRIDE].ravel().astype(np.float64)
            lo, hi = _quantiles(vals, TRIM)
            core = vals[(vals >= lo) & (vals <= hi)]
            assert robust_mean_std(d, valid, 1e-6) == (float(core.mean()), max(float(core.std()), 1e-6))
