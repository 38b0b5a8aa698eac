"""RANSAC plane baseline: a box on a tilted floor comes out as the object."""

from __future__ import annotations

import math

import numpy as np
import pytest

from edge.baseline import Intrinsics, PlaneBaseline, back_project, intrinsics_for
from edge.errors import ConfigError, DataError
from edge.meta import SensorSpec, fov_intrinsics
from edge.metrics import confusion, frame_scores


def tilted_scene(h=171, w=224, tilt_deg=20.0, box_h=0.03, noise=0.001, seed=0):
    """Z-depth of a floor tilted about the camera x axis with a raised square box top on it."""
    fx, fy, cx, cy = fov_intrinsics(w, h, 62.0, 45.0)
    v, u = np.mgrid[0:h, 0:w].astype(np.float64)
    rays = np.stack([(u - cx) / fx, (v - cy) / fy, np.ones_like(u)], axis=-1)
    a = math.radians(tilt_deg)
    m = np.array([0.0, math.sin(a), math.cos(a)])  # floor normal, pointing away from the camera
    p0 = np.array([0.0, 0.0, 0.3])
    mr = rays @ m
    t_floor = (m @ p0) / mr
    t_top = (m @ p0 - box_h) / mr
    top = rays * t_top[..., None]
    # in-plane axes of the floor
    e1 = np.array([1.0, 0.0, 0.0])
    e2 = np.cross(m, e1)
    rel = top - (p0 - box_h * m)
    inside = (np.abs(rel @ e1) < 0.04) & (np.abs(rel @ e2 - 0.01) < 0.03)
    z = np.where(inside, t_top, t_floor)
    rng = np.random.default_rng(seed)
    z = z + rng.normal(0.0, noise, z.shape)
    z = z.astype(np.float32)
    z[:4, :4] = 0.0
    z[-3:, -5:] = np.nan
    z[10, 10:20] = -1.0
    return z, inside.astype(np.uint8), Intrinsics(fx, fy, cx, cy)


def test_box_on_tilted_floor_is_the_object():
    depth, label, k = tilted_scene()
    assert 500 < label.sum() < depth.size // 4
    b = PlaneBaseline()
    pred = b.predict(depth, k)
    valid = np.isfinite(depth) & (depth > 0)
    s = frame_scores(confusion(pred, label, valid))
    assert s.iou > 0.95 and s.precision > 0.97 and s.recall > 0.95
    assert not pred[~valid].any()
    h = b.heights(depth, k)
    assert np.median(h[label.astype(bool) & valid]) == pytest.approx(0.03, abs=0.002)
    assert abs(np.median(h[~label.astype(bool) & valid])) < 0.001
    sc = b.scores(depth, k)
    assert np.array_equal(sc > 0, pred)


def test_deterministic_for_a_seed():
    depth, _, k = tilted_scene(h=64, w=96, noise=0.004, seed=3)
    b = PlaneBaseline(seed=5, iterations=50)
    assert np.array_equal(b.heights(depth, k), b.heights(depth, k))


def test_back_project_matches_pinhole():
    k = Intrinsics(100.0, 100.0, 2.0, 1.0)
    depth = np.full((3, 5), 0.5, np.float32)
    depth[0, 0] = 0
    pts = back_project(depth, k)
    assert pts.shape == (14, 3)
    # pixel (v=2, u=4) is the last one
    assert pts[-1] == pytest.approx([(4 - 2) / 100 * 0.5, (2 - 1) / 100 * 0.5, 0.5])


def test_too_few_points_gives_all_background():
    depth = np.zeros((20, 30), np.float32)
    depth[0, :5] = 0.3
    k = intrinsics_for(depth.shape)
    assert not PlaneBaseline().predict(depth, k).any()


def test_intrinsics_from_camera_info_then_sensor():
    info = {"fx": 200.0, "fy": 201.0, "cx": 110.0, "cy": 85.0, "height": 171, "width": 224, "d": [0.1, 0, 0, 0, 0]}
    k = intrinsics_for((171, 224), info)
    assert (k.fx, k.fy, k.cx, k.cy, k.distortion) == (200.0, 201.0, 110.0, 85.0, (0.1, 0.0, 0.0, 0.0, 0.0))
    s = SensorSpec()
    assert intrinsics_for((171, 224), None, s).fx == s.fx
    small = intrinsics_for((s.height // 2, s.width // 2), None, s)
    assert small.fx == pytest.approx(s.fx * (s.width // 2) / s.width)
    with pytest.raises(DataError, match="camera_info"):
        intrinsics_for((100, 100), info)


def test_distortion_is_undone():
    depth, _, k = tilted_scene(h=40, w=60, noise=0.0)
    kd = Intrinsics(k.fx, k.fy, k.cx, k.cy, (1e-9, 0.0, 0.0, 0.0, 0.0))
    assert back_project(depth, kd) == pytest.approx(back_project(depth, k), abs=1e-6)


def test_median_removes_isolated_noise_detections():
    depth, label, k = tilted_scene(noise=0.004, seed=1)  # 8 mm threshold = 2 sigma: ~2 % of the floor
    floor = ~label.astype(bool)
    raw = PlaneBaseline(median_px=0).predict(depth, k)
    smooth = PlaneBaseline(median_px=3).predict(depth, k)
    assert raw[floor].mean() > 0.01
    assert smooth[floor].mean() < raw[floor].mean() / 5
    assert smooth[label.astype(bool)].mean() > 0.95


def test_bad_parameters():
    with pytest.raises(ConfigError):
        PlaneBaseline(height_threshold_m=0)
    with pytest.raises(ConfigError):
        PlaneBaseline(iterations=0)
    with pytest.raises(ConfigError, match="median"):
        PlaneBaseline(median_px=4)
