"""The ToF sensor model on synthetic renders whose right answers are known by construction."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from sim.render import Camera, RenderResult, ray_grid
from sim.sensor import FrameDraw, SensorConfig, apply_sensor

CAM = Camera()
GRID = ray_grid(CAM)
H, W = CAM.height, CAM.width


def _render(z: np.ndarray, ids: np.ndarray, height: np.ndarray | None = None, edge=None, sub_r=None, sub_ids=None):
    e = np.zeros(0, np.int64) if edge is None else np.asarray(edge)
    s = 4
    return RenderResult(
        z=z.astype(np.float32),
        r=(z * GRID.norm).astype(np.float32),
        ids=ids.astype(np.int32),
        cos_inc=np.ones((H, W), np.float32),
        height=np.zeros((H, W), np.float32) if height is None else height.astype(np.float32),
        edge=e,
        sub_r=np.zeros((0, s), np.float32) if sub_r is None else sub_r.astype(np.float32),
        sub_ids=np.zeros((0, s), np.int32) if sub_ids is None else sub_ids.astype(np.int32),
        sub_cos=np.ones((len(e), s), np.float32),
    )


def _draw(albedo_floor=0.6, objects=(), exposure=1.0, noise=1.0, mp=0.0, cone=32.0):
    return FrameDraw(albedo_floor, np.asarray(objects, float), exposure, noise, mp, cone)


def _floor(z=0.3):
    return _render(np.full((H, W), z), np.zeros((H, W)))


def test_ideal_sensor_returns_the_clean_depth():
    rr = _floor()
    out = apply_sensor(rr, GRID, CAM.fx, 0.3, _draw(), SensorConfig.ideal(), np.random.default_rng(0))
    np.testing.assert_allclose(out.depth, rr.z, rtol=1e-6)
    assert out.valid.all()


def test_corners_die_and_the_centre_lives():
    rr = _floor()
    out = apply_sensor(rr, GRID, CAM.fx, 0.3, _draw(cone=32.2), SensorConfig(), np.random.default_rng(0))
    inv = ~out.valid
    assert 0.015 < inv.mean() < 0.06  # SENSOR.md: about 3 % of the frame
    for corner in (inv[:12, :12], inv[:12, -12:], inv[-12:, :12], inv[-12:, -12:]):
        assert corner.mean() > 0.9  # all four corners
    assert inv[40:-40, 50:-50].mean() < 0.005
    assert np.all(out.depth[inv] == 0) and np.all(out.depth[~inv] > 0)


def test_noise_level_matches_the_real_floor_and_is_correlated():
    rr = _floor(0.3)
    out = apply_sensor(rr, GRID, CAM.fx, 0.3, _draw(), SensorConfig(), np.random.default_rng(1))
    assert out.valid[60:110, 80:140].mean() > 0.99
    d = np.where(out.valid, out.depth - rr.z, 0.0)[60:110, 80:140]
    # real capture (shared/data/royale), robust local residual: ~0.7-0.9 mm at 35 cm
    assert 0.0005 < d.std() < 0.0015
    # neighbours correlate (Royale's 3x3 smoothing), far pixels do not
    near = np.corrcoef(d[:, :-1].ravel(), d[:, 1:].ravel())[0, 1]
    far = np.corrcoef(d[:, :-5].ravel(), d[:, 5:].ravel())[0, 1]
    assert near > 0.4 and abs(far) < 0.1


def test_noise_grows_with_range_and_falls_with_albedo():
    ids = np.zeros((H, W))
    ids[:, W // 2 :] = 1  # right half: object 0
    z = np.full((H, W), 0.3)
    cfg = dataclasses.replace(
        SensorConfig(), correlated=False, mixed_pixels=False, flying_filter=False, dead_pixel_fraction=0.0, amplitude_min=0.0
    )
    rng = np.random.default_rng(2)
    # same range, albedo 4x lower on the right: sigma 2x higher
    out = apply_sensor(_render(z, ids), GRID, CAM.fx, 0.3, _draw(0.8, [0.2]), cfg, rng)
    err = out.depth - z
    left, right = err[50:120, 40:100].std(), err[50:120, 124:184].std()
    assert right / left == pytest.approx(2.0, rel=0.15)
    # same albedo, right half twice as far: amplitude 4x lower, sigma 2x higher (range noise grows)
    z2 = z.copy()
    z2[:, W // 2 :] = 0.6
    out = apply_sensor(_render(z2, ids), GRID, CAM.fx, 0.3, _draw(0.5, [0.5]), cfg, rng)
    err = out.depth - z2
    assert err[50:120, 124:184].std() / err[50:120, 40:100].std() == pytest.approx(2.0, rel=0.15)


def _step(flying_filter: bool, mixed: bool, miss: float = 0.0):
    """Floor at 0.30 m, an object face at 0.20 m on the right half; one mixed column between."""
    z = np.full((H, W), 0.30)
    ids = np.zeros((H, W))
    z[:, 113:] = 0.20
    ids[:, 113:] = 1
    col = 112  # pixels whose footprint straddles the edge: two sub-rays on each surface
    edge = np.arange(H) * W + col
    r0 = 0.30 * GRID.norm[:, col]
    r1 = 0.20 * GRID.norm[:, col]
    sub_r = np.stack([r0, r0, r1, r1], 1)
    sub_ids = np.tile([0, 0, 1, 1], (H, 1))
    rr = _render(z, ids, edge=edge, sub_r=sub_r, sub_ids=sub_ids)
    cfg = dataclasses.replace(SensorConfig.ideal(), flying_filter=flying_filter, mixed_pixels=mixed, flying_miss_prob=miss)
    return apply_sensor(rr, GRID, CAM.fx, 0.3, _draw(0.5, [0.5]), cfg, np.random.default_rng(0)), col


def test_mixed_pixels_fly_between_surfaces_and_royale_filter_removes_them():
    out, col = _step(flying_filter=False, mixed=True)
    mid = out.depth[60:110, col]
    # equal albedo: the nearer surface returns 2.25x the light, so the blend leans towards it
    assert np.all((mid > 0.205) & (mid < 0.25))
    out, col = _step(flying_filter=True, mixed=True)
    assert np.all(out.depth[5:-5, col] == 0)  # > 18 mm from both horizontal neighbours
    assert np.all(out.depth[60:110, col + 1] > 0) and np.all(out.depth[60:110, col - 1] > 0)
    out, col = _step(flying_filter=False, mixed=False)
    np.testing.assert_allclose(out.depth[60:110, col], 0.30, atol=1e-6)  # no mixing: clean edge


def test_flying_filter_misses_the_configured_share():
    """The real capture keeps some flying pixels: ``flying_miss_prob`` lets that share through."""
    out, col = _step(flying_filter=True, mixed=True, miss=0.3)
    kept = out.depth[5:-5, col] > 0
    assert 0.15 < kept.mean() < 0.45  # 161 Bernoulli(0.3) draws
    mid = out.depth[5:-5, col][kept]
    assert np.all((mid > 0.205) & (mid < 0.25))  # the survivors still read in between
    out, col = _step(flying_filter=True, mixed=True, miss=1.0)
    assert np.all(out.depth[5:-5, col] > 0)


def test_flying_miss_prob_zero_keeps_the_config_digest_and_is_checked():
    from edge.errors import ConfigError

    assert "flying_miss_prob" not in SensorConfig().to_dict()
    assert SensorConfig(flying_miss_prob=0.03).to_dict()["flying_miss_prob"] == 0.03
    with pytest.raises(ConfigError, match="flying_miss_prob"):
        SensorConfig(flying_miss_prob=1.5)


def test_multipath_biases_floor_near_tall_objects_only():
    z = np.full((H, W), 0.30)
    ids = np.zeros((H, W))
    height = np.zeros((H, W))
    ids[70:100, 100:124] = 1
    z[70:100, 100:124] = 0.22
    height[70:100, 100:124] = 0.08  # an 8 cm tall object
    cfg = dataclasses.replace(SensorConfig.ideal(), multipath_max_m=0.01)
    out = apply_sensor(_render(z, ids, height), GRID, CAM.fx, 0.3, _draw(0.5, [0.5], mp=0.12), cfg, np.random.default_rng(0))
    bias = (out.depth - z) * GRID.norm  # back to range
    near = bias[85, 126:130]
    assert np.all(near > 0.001) and np.all(near <= 0.01 + 1e-6)
    assert np.abs(bias[5:20, 5:30]).max() < 1e-4  # far floor untouched
    np.testing.assert_allclose(out.depth[75:95, 105:120], 0.22, atol=1e-6)  # the object itself is not


def test_saturation_dead_pixels_and_range_limits():
    z = np.full((H, W), 0.30)
    ids = np.zeros((H, W))
    z[80:90, 100:110] = 0.05  # closer than the 0.1 m minimum range
    cfg = dataclasses.replace(SensorConfig(), dead_pixel_fraction=0.01)
    out = apply_sensor(_render(z, ids), GRID, CAM.fx, 0.3, _draw(), cfg, np.random.default_rng(3))
    assert np.all(out.depth[80:90, 100:110] == 0)
    centre = ~out.valid[30:-30, 40:-40]
    assert 0.005 < centre.mean() < 0.02  # ~1 % random dead pixels
    ids[20:40, 20:40] = 1
    z[20:40, 20:40] = 0.25
    cfg = dataclasses.replace(SensorConfig(), amplitude_max=3.0)
    out = apply_sensor(_render(z, ids), GRID, CAM.fx, 0.3, _draw(0.2, [5.0]), cfg, np.random.default_rng(3))
    assert np.all(out.depth[22:38, 22:38] == 0)  # a very bright object saturates


def test_same_generator_same_output():
    rr = _floor()
    a = apply_sensor(rr, GRID, CAM.fx, 0.3, _draw(), SensorConfig(), np.random.default_rng(9))
    b = apply_sensor(rr, GRID, CAM.fx, 0.3, _draw(), SensorConfig(), np.random.default_rng(9))
    np.testing.assert_array_equal(a.depth, b.depth)


def test_psf_mixes_returns_across_edges_weighted_by_amplitude():
    z = np.full((H, W), 0.30)
    ids = np.zeros((H, W))
    z[:, 112:] = 0.25
    ids[:, 112:] = 1
    cfg = SensorConfig.ideal()
    rr = _render(z, ids)
    blurred = apply_sensor(rr, GRID, CAM.fx, 0.3, dataclasses.replace(_draw(0.5, [0.5]), psf_sigma_px=1.0), cfg,
                           np.random.default_rng(0))
    row = blurred.depth[85] * GRID.norm[85]  # range along one row
    r_clean = rr.r[85]
    near, far = 0.25 * GRID.norm[85, 110:114], 0.30 * GRID.norm[85, 110:114]
    assert np.all((row[110:114] > near + 0.001) & (row[110:114] < far - 0.001))  # two pixels each side fly
    np.testing.assert_allclose(row[3:100], r_clean[3:100], atol=2e-4)  # flat floor stays put (off the border)
    np.testing.assert_allclose(row[125:-3], r_clean[125:-3], atol=2e-4)
    # a dark object loses the tug of war: the mixed pixels lean towards the bright floor
    dark = apply_sensor(rr, GRID, CAM.fx, 0.3, dataclasses.replace(_draw(0.8, [0.1]), psf_sigma_px=1.0), cfg,
                        np.random.default_rng(0))
    assert np.all(dark.depth[85, 111:113] > blurred.depth[85, 111:113])
