"""Realism metrics on synthetic frames whose answers are known by construction."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from edge.errors import DataError
from sim import realism as rl

H, W = 171, 224
ROYALE = Path(__file__).resolve().parents[2].parent / "shared" / "data" / "royale" / "royale_20200513_203219_0.ply"


def _flat(z: float = 0.3) -> np.ndarray:
    return np.full((H, W), z, dtype=np.float32)


def test_corner_masks_partition_the_outside_of_the_ellipse():
    masks = rl.corner_masks((H, W))
    total = sum(m.astype(int) for m in masks.values())
    assert total.max() == 1  # disjoint
    assert total.mean() == pytest.approx(1 - np.pi / 4, abs=0.01)  # outside the inscribed ellipse
    assert masks["tl"][0, 0] and masks["tr"][0, -1] and masks["bl"][-1, 0] and masks["br"][-1, -1]
    assert not total[H // 2, W // 2] and not total[0, W // 2] and not total[H // 2, 0]


def test_dead_corners_known_fraction():
    d = _flat()
    masks = rl.corner_masks((H, W))
    d[masks["tl"]] = 0.0  # the whole top-left corner region is dead
    d[:10, -10:] = np.nan  # a 10 x 10 block in the top-right corner (NaN counts as invalid)
    s = rl.invalid_stats(d)
    n_tl = int(masks["tl"].sum())
    assert s.fraction == pytest.approx((n_tl + 100) / (H * W))
    assert s.corner_share == 1.0 and s.edge_share == 0.0 and s.other_share == 0.0
    assert s.corner_fill["tl"] == 1.0
    assert s.corner_fill["tr"] == pytest.approx(100 / masks["tr"].sum())
    assert s.corner_fill["bl"] == 0.0 and s.corner_fill["br"] == 0.0


def test_invalid_at_object_edges_vs_elsewhere():
    d = _flat()
    d[60:110, 80:150] = 0.25  # a 5 cm box
    d[60:110, 79] = 0.0  # the flying-pixel filter removed the column left of it: 50 px
    rng = np.random.default_rng(1)
    free = np.zeros((H, W), bool)
    free[20:40, 40:70] = True  # flat floor, far from the box and inside the ellipse
    idx = rng.choice(np.flatnonzero(free), 20, replace=False)
    d.ravel()[idx] = -1.0  # random dead pixels (negative is invalid too)
    s = rl.invalid_stats(d)
    assert s.fraction == pytest.approx(70 / (H * W))
    assert s.edge_share == pytest.approx(50 / 70)
    assert s.other_share == pytest.approx(20 / 70)
    assert s.corner_share == 0.0


def _tilted_floor(tilt: float = 0.2, z0: float = 0.3) -> np.ndarray:
    """A true 3-D plane seen by the default pinhole: 1/Z is linear in the normalised x."""
    fx, _, cx, _ = rl._default_intrinsics((H, W))
    xn = (np.arange(W) - cx) / fx
    return np.broadcast_to(z0 / (1 - tilt * xn), (H, W)).astype(np.float64)


def test_white_noise_sigma_is_recovered():
    sigma = 0.002
    rng = np.random.default_rng(7)
    d = _tilted_floor() + rng.normal(0, sigma, (H, W))
    n = rl.floor_noise(d, rng=np.random.default_rng(0))
    assert n.floor_fraction > 0.99  # a 10 mm band holds +-5 sigma
    assert n.tiles > 500
    assert n.sigma_patch == pytest.approx(sigma, rel=0.05)
    assert n.sigma_diff == pytest.approx(sigma, rel=0.05)


def test_correlated_noise_lowers_only_the_neighbour_estimate():
    rng = np.random.default_rng(3)
    white = rng.normal(0, 0.006, (H + 2, W + 2))
    blurred = sum(white[i : i + H, j : j + W] for i in range(3) for j in range(3)) / 9.0  # 3x3 box
    sigma = 0.006 / 3.0  # std after a 3x3 box blur of white noise
    d = _flat() + blurred
    n = rl.floor_noise(d, floor=np.ones((H, W), bool))
    # neighbours share 6 of 9 samples: var(diff) = 2 sigma^2 (1 - 2/3) -> sigma_diff = sigma / sqrt(3)
    assert n.sigma_diff == pytest.approx(sigma / np.sqrt(3), rel=0.06)
    # a tile's plane fit absorbs part of correlated noise: expected residual variance is
    # trace((I - P) C) / (n - 3), C the box-blur covariance (overlap of 3x3 windows / 81)
    v, u = np.mgrid[0:8, 0:8].reshape(2, -1)
    overlap = np.clip(3 - np.abs(u[:, None] - u[None, :]), 0, None) * np.clip(3 - np.abs(v[:, None] - v[None, :]), 0, None)
    cov = 0.006**2 * overlap / 81.0
    a = np.stack([u, v, np.ones_like(u)], axis=1).astype(float)
    resid = np.eye(64) - a @ np.linalg.pinv(a)
    expected = np.sqrt(np.trace(resid @ cov) / 61)
    assert 0.75 * sigma < expected < 0.9 * sigma
    assert n.sigma_patch == pytest.approx(expected, rel=0.05)


def test_floor_excludes_objects_and_noise_ignores_them():
    rng = np.random.default_rng(5)
    d = _tilted_floor() + rng.normal(0, 0.001, (H, W))
    d[50:120, 60:160] -= 0.05
    floor = rl.floor_mask(d, rng=np.random.default_rng(0))
    assert not floor[50:120, 60:160].any()
    assert floor.sum() == pytest.approx(H * W - 70 * 100, rel=0.002)
    n = rl.floor_noise(d, rng=np.random.default_rng(0))
    assert n.sigma_patch == pytest.approx(0.001, rel=0.06)


def test_flying_pixels_known_count():
    d = _flat()
    d[50:120, 100:140] = 0.25  # 70 x 40 box, 5 cm above the floor
    d[60:70, 99] = 0.275  # 10 mixed returns halfway between floor and box
    d[20, 30] = 0.35  # a spike: off both neighbours, but not between them
    stats, mask = rl.flying_pixels(d)
    assert stats.flying_pixels == 10 and mask[60:70, 99].all()
    # box border 216 + floor pixels touching it 220 + floor behind the mixed ones 10 + spike and its 4 neighbours
    assert stats.edge_pixels == 216 + 220 + 10 + 5
    assert stats.fraction == pytest.approx(10 / 451)


def test_clean_step_has_no_flying_pixels_and_small_steps_are_not_edges():
    d = _flat()
    d[50:120, 100:140] = 0.25
    d[10:20, 10:20] += 0.01  # 10 mm: below Royale's 18 mm rule
    stats, _ = rl.flying_pixels(d)
    assert stats.flying_pixels == 0 and stats.edge_pixels == 436


def test_edge_sharpness_is_two_for_an_ideal_step_and_zero_when_blurred():
    d = _flat()
    d[50:120, 100:140] = 0.25  # 70 x 40 box, 5 cm high: 216 outline pixels, 436 sharp-edge pixels
    floor = rl.floor_mask(d, rng=np.random.default_rng(0))
    crisp = rl.edge_sharpness(d, floor)
    assert crisp.outline_pixels == 216 and crisp.sharpness == pytest.approx(436 / 216)
    ramp = d.copy()  # the 50 mm step spread over three rings: every 4-neighbour step is 12.5 mm < 18 mm
    for k, z in enumerate((0.2625, 0.275, 0.2875)):  # ring k lies k + 1 px outside the box
        ramp[50 - 1 - k : 120 + 1 + k, 100 - 1 - k] = z
        ramp[50 - 1 - k : 120 + 1 + k, 140 + k] = z
        ramp[50 - 1 - k, 100 - 1 - k : 140 + 1 + k] = z
        ramp[120 + k, 100 - 1 - k : 140 + 1 + k] = z
    blurred = rl.edge_sharpness(ramp, rl.floor_mask(ramp, rng=np.random.default_rng(0)))
    assert blurred.outline_pixels > 0 and blurred.sharpness == 0.0
    assert np.isnan(rl.edge_sharpness(_flat(), np.ones((H, W), bool)).sharpness)  # no objects, no outline


def test_invalid_edge_pixels_per_valid_edge_pixel():
    d = _flat()
    d[60:110, 80:150] = 0.25  # a 5 cm box
    d[60:110, 79] = 0.0  # the flying-pixel filter removed the column left of it: 50 px
    r = rl.realism(d)
    assert r.edges.invalid_per_edge_pixel == pytest.approx(50 / rl.flying_pixels(d)[0].edge_pixels)
    assert np.isnan(rl.realism(_flat()).edges.invalid_per_edge_pixel)  # no edges


def test_realism_rejects_tiny_frames():
    with pytest.raises(DataError, match="at least 16 px"):
        rl.realism(np.ones((4, 4)))


def test_real_capture_has_dead_corners():
    if not ROYALE.exists():
        pytest.skip(f"{ROYALE} is absent (shared data lives at ../shared next to the repo)")
    from sim.importers import fit_intrinsics, read_ply

    cap = read_ply(ROYALE)
    k, _ = fit_intrinsics(cap.points, cap.valid)
    r = rl.realism(cap.depth, k)
    assert r.invalid.fraction == pytest.approx(float((cap.points[..., 2] == 0).mean()))
    assert r.invalid.corner_share > 0.5  # the paper (V.e): dead pixels always in all four corners
    assert all(v > 0.02 for v in r.invalid.corner_fill.values())
    assert r.invalid.corner_share + r.invalid.edge_share + r.invalid.other_share == pytest.approx(1.0)
    assert 0.0002 < r.noise.sigma_patch < 0.005 and r.noise.tiles > 50
