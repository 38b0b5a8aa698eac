"""Scene configuration: Table I defaults, validation, and what a sampled scene looks like."""

from __future__ import annotations

import math

import numpy as np
import pytest

from edge.errors import ConfigError
from sim.generate import SimConfig
from sim.physics import PhysicsConfig
from sim.scene import SceneConfig, camera_rotation, quat_to_matrix, sample_scene
from sim.sensor import SensorConfig


def test_defaults_are_table_one():
    c = SceneConfig()
    assert c.n_objects == (0, 20)
    assert c.largest_dim_m == (0.04, 0.10)
    assert c.object_xy_m == (-0.075, 0.075)
    assert c.drop_step_m == 0.10
    assert c.euler_rad == (0.0, math.pi)
    assert c.camera_xy_m == (0.0, 0.0)
    assert c.camera_height_m == (0.20, 0.40)
    assert c.camera_yaw_rad == (-math.pi, math.pi)
    assert c.camera_tilt_rad == (-math.pi / 18, math.pi / 18)


@pytest.mark.parametrize(
    "section,key,value,match",
    [
        ("scene", "camera_height_m", [0.4, 0.2], "min 0.4 is above max 0.2"),
        ("scene", "largest_dim_m", [0.1, 0.04], "above max"),
        ("scene", "n_objects", [5, 2], "above max"),
        ("scene", "n_objects", [0.5, 2], "whole number"),
        ("scene", "shapes", ["box", "blob"], "unknown"),
        ("scene", "min_thickness_m", 0.05, "above the smallest largest_dim_m"),
        ("scene", "colour", 1, "unknown scene keys"),
        ("sensor", "albedo_floor", [0.9, 0.1], "above max"),
        ("sensor", "dead_pixel_fraction", 2.0, "outside"),
        ("physics", "timestep_s", 1.0, "outside"),
        ("camera", "fx", -3, "positive"),
        ("camera", "distortion", [0.1, 0.2], "plumb_bob takes 5"),
    ],
)
def test_bad_values_raise_config_error(section, key, value, match):
    with pytest.raises(ConfigError, match=match):
        SimConfig.from_dict({section: {key: value}})


def test_config_round_trips_through_json_dict():
    c = SimConfig.from_dict({"scene": {"n_objects": [1, 3]}, "sensor": {"noise_scale": [1, 1]}})
    again = SimConfig.from_dict(c.to_dict())
    assert again == c and again.digest() == c.digest()
    assert c.digest() != SimConfig().digest()
    assert SceneConfig(shapes=("box", "sphere")).shape_weights == (2.0, 1.0)  # defaults follow the subset
    assert isinstance(PhysicsConfig.from_dict(None), PhysicsConfig)
    assert isinstance(SensorConfig.from_dict({}), SensorConfig)


def test_sampled_scenes_follow_the_ranges():
    cfg = SceneConfig()
    counts = []
    for i in range(30):
        s = sample_scene(np.random.default_rng(i), cfg)
        counts.append(len(s.objects))
        assert 0.20 <= s.camera_height <= 0.40
        assert abs(s.tilt_x) <= math.pi / 18 and abs(s.tilt_y) <= math.pi / 18
        r = s.camera_rotation
        np.testing.assert_allclose(r @ r.T, np.eye(3), atol=1e-12)
        # optical axis points down, within the tilt range
        assert r[:, 2] @ [0, 0, -1] >= math.cos(math.hypot(math.pi / 18, math.pi / 18)) - 1e-9
        for k, o in enumerate(s.objects):
            assert -0.075 <= o.pos[0] <= 0.075 and -0.075 <= o.pos[1] <= 0.075
            lowest = (o.shape.vertices.astype(float) @ quat_to_matrix(o.quat).T + o.pos)[:, 2].min()
            # Table I: object k released at 10 k cm (plus a small clearance)
            assert lowest == pytest.approx(k * 0.10 + cfg.drop_clearance_m, abs=1e-6)
            assert 0.04 * 0.97 <= o.shape.extents.max() <= 0.10 * 1.03
    assert min(counts) >= 0 and max(counts) <= 20 and len(set(counts)) > 5


def test_camera_rotation_without_tilt_looks_straight_down():
    r = camera_rotation(0.0, 0.0, 0.0)
    np.testing.assert_allclose(r[:, 2], [0, 0, -1])  # optical axis
    np.testing.assert_allclose(r[:, 0], [1, 0, 0])  # image x = world x
