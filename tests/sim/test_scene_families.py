"""Scene families where a floor-plane fit fails: thin objects, table edges, curved supports,
trays; and long objects (handles, rods) that Table I never had. Each is off by default (default frames unchanged) and validated like the other keys."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from edge.errors import ConfigError
from sim.generate import SimConfig, generate_frame
from sim.render import ray_grid
from sim.scene import SceneConfig, camera_rotation, quat_to_matrix, sample_scene
from sim.shapes import LONG_KINDS, THIN_KINDS, make_long_shape, make_thin_shape

FAMILIES = Path(__file__).resolve().parents[2] / "tools" / "scene_families"


def _world(f, cfg: SimConfig) -> np.ndarray:
    """World point (H, W, 3) of every pixel's clean hit (from the recorded camera pose)."""
    cam = f.scene["params"]["camera"]
    r_wc = camera_rotation(cam["yaw_rad"], cam["tilt_x_rad"], cam["tilt_y_rad"])
    origin = np.array([*cam["xy_m"], cam["height_m"]])
    return origin + f.clean[..., None] * (ray_grid(cfg.camera).dirs @ r_wc.T)


def _world_z(f, cfg: SimConfig) -> np.ndarray:
    return _world(f, cfg)[..., 2]


def test_family_keys_are_off_by_default_and_keep_the_digest():
    c = SceneConfig()
    assert c.thin_fraction == 0.0
    assert "thin_fraction" not in c.to_dict()  # old configs keep their digest and output dirs
    assert SimConfig.from_dict({"scene": {"thin_fraction": 0.0}}).digest() == SimConfig().digest()
    assert SimConfig.from_dict({"scene": {"thin_fraction": 0.3}}).digest() != SimConfig().digest()


@pytest.mark.parametrize(
    "key,value,match",
    [
        ("thin_fraction", 1.5, "scene.thin_fraction"),
        ("thin_thickness_m", [0.008, 0.003], "above max"),
        ("thin_thickness_m", [0.003, 0.2], "scene.thin_thickness_m"),
        ("thin_shapes", ["disc", "spoon"], "scene.thin_shapes"),
        ("long_fraction", -0.2, "scene.long_fraction"),
        ("long_length_m", [0.3, 0.1], "above max"),
        ("long_diameter_m", [0.0, 0.02], "scene.long_diameter_m: min 0.0 is below"),
        ("long_shapes", ["rod", "broom"], "scene.long_shapes"),
        ("support_curvature", [-3.0, 0.5], "scene.support_curvature: min -3.0 is below"),
        ("table_edge_prob", -0.1, "scene.table_edge_prob"),
        ("floor_drop_m", [0.5, 0.2], "above max"),
        ("tray_prob", 2, "scene.tray_prob"),
        ("tray_wall_height_m", [0.0, 0.05], "scene.tray_wall_height_m: min 0.0 is below"),
        ("empty_prob", 1.2, "scene.empty_prob"),
    ],
)
def test_bad_family_values_are_one_line_config_errors(key, value, match):
    with pytest.raises(ConfigError, match=match) as exc:
        SimConfig.from_dict({"scene": {key: value}})
    assert "\n" not in str(exc.value)


def test_empty_prob_empties_that_share_of_scenes_and_is_off_by_default():
    assert "empty_prob" not in SceneConfig().to_dict()
    assert SimConfig.from_dict({"scene": {"empty_prob": 0.0}}).digest() == SimConfig().digest()
    cfg = SceneConfig(n_objects=(5, 10), empty_prob=0.25)
    rng = np.random.default_rng(7)
    counts = [len(sample_scene(rng, cfg).objects) for _ in range(400)]
    empty = sum(c == 0 for c in counts) / len(counts)
    assert 0.18 < empty < 0.32  # 0.25 +- ~4 sigma; n_objects alone never gives 0 here
    assert all(c == 0 or 5 <= c <= 10 for c in counts)
    full = SceneConfig(n_objects=(5, 10), empty_prob=1.0)
    assert not sample_scene(np.random.default_rng(1), full).objects


@pytest.mark.parametrize("kind", THIN_KINDS)
def test_thin_shapes_are_flat_with_the_requested_size(kind):
    s = make_thin_shape(kind, np.random.default_rng(1), 0.08, 0.004)
    np.testing.assert_allclose(s.extents.max(), 0.08, rtol=0.03)
    assert s.extents[2] == pytest.approx(0.004, rel=1e-4)
    assert s.params["thin"] and s.parts


def test_thin_objects_take_the_lowest_slots():
    cfg = SceneConfig(n_objects=(10, 10), thin_fraction=0.5)
    scene = sample_scene(np.random.default_rng(4), cfg)
    thin = [o.shape.params.get("thin", False) for o in scene.objects]
    n = sum(thin)
    assert 0 < n < 10 and thin == [True] * n + [False] * (10 - n)


def test_long_family_is_off_by_default_and_keeps_the_digest():
    assert "long_fraction" not in SceneConfig().to_dict()
    assert SimConfig.from_dict({"scene": {"long_fraction": 0.0}}).digest() == SimConfig().digest()
    assert SimConfig.from_dict({"scene": {"long_fraction": 0.1}}).digest() != SimConfig().digest()


@pytest.mark.parametrize("kind", LONG_KINDS)
def test_long_shapes_have_the_requested_length_and_girth(kind):
    s = make_long_shape(kind, np.random.default_rng(1), 0.25, 0.02)
    assert s.extents[2] == pytest.approx(0.25, rel=0.03)  # along body z
    assert 0.009 < s.extents[:2].min() <= s.extents[:2].max() < 0.032
    assert s.params["long"] and s.parts


def test_long_objects_take_the_highest_slots_and_fall_last():
    cfg = SceneConfig(n_objects=(10, 10), long_fraction=0.5)
    scene = sample_scene(np.random.default_rng(4), cfg)
    long_ = [o.shape.params.get("long", False) for o in scene.objects]
    n = sum(long_)
    assert 0 < n < 10 and long_ == [False] * (10 - n) + [True] * n
    for o in scene.objects[10 - n:]:  # released lying: the long axis within 0.3 rad of level
        assert abs(quat_to_matrix(o.quat)[2, 2]) < np.sin(0.3) + 1e-9


def test_long_objects_settle_and_are_labelled_past_table_i_size():
    cfg = SimConfig.from_dict({"scene": {"n_objects": [3, 3], "long_fraction": 1.0, "long_length_m": [0.2, 0.2]}})
    f = generate_frame(0, 3, cfg)
    objs = f.scene["params"]["objects"]
    assert all(o["long"] for o in objs)
    assert all(o["rest_pos_m"][2] < 0.2 for o in objs)  # they came to rest, none left in the air
    world = _world(f, cfg)[f.label == 1]
    assert np.ptp(world[:, 0]) > 0.12 or np.ptp(world[:, 1]) > 0.12  # longer than Table I's 10 cm


def test_thin_objects_rest_flat_and_are_labelled():
    cfg = SimConfig.from_dict({"scene": {"n_objects": [3, 3], "thin_fraction": 1.0}})
    for i in range(3):
        f = generate_frame(i, 7, cfg)
        objs = f.scene["params"]["objects"]
        assert all(o["thin"] and o["thickness_m"] < 0.01 for o in objs)
        for o in objs:
            up = quat_to_matrix(np.array(o["rest_quat"]))[2, 2]
            assert abs(up) > 0.9 or o["rest_pos_m"][2] > 0.006  # flat on the floor, or on another one
        z = _world_z(f, cfg)
        assert f.label.sum() > 200  # thin objects are objects
        assert z[f.label == 1].max() < 0.03  # ... and barely stand out of the floor


def test_family_configs_validate_and_have_no_sensor_section():
    files = sorted(FAMILIES.glob("*.json"))
    assert files
    for p in files:
        d = json.loads(p.read_text())
        assert set(d) == {"scene"}, p.name  # the sensor section is merged in elsewhere
        assert SimConfig.from_dict(d).digest() != SimConfig().digest(), p.name


def test_beyond_the_table_edge_is_far_background():
    cfg = SimConfig.from_dict({"scene": {
        "n_objects": [2, 4], "table_edge_prob": 1.0, "table_edge_dist_m": [0.1, 0.1],
        "floor_drop_m": [0.5, 0.5], "camera_height_m": [0.35, 0.35]}})
    for i in range(3):
        f = generate_frame(i, 3, cfg)
        edge = f.scene["params"]["support"]["table_edge"]
        assert edge["floor_drop_m"] == 0.5 and edge["dist_m"] >= 0.1
        z = _world_z(f, cfg)
        low = (f.clean > 0) & (z < -0.25)
        assert low.sum() > 500  # the room floor is in view ...
        np.testing.assert_allclose(z[low], -0.5, atol=2e-3)  # ... half a metre down
        assert not f.label[low].any()  # ... and background
        assert f.clean[low].min() > 0.8
        table = (f.label == 0) & (f.clean > 0) & ~low
        np.testing.assert_allclose(z[table], 0.0, atol=2e-4)


def test_table_edge_must_clear_the_object_area():
    with pytest.raises(ConfigError, match="scene.table_edge_dist_m min 0.05 must exceed"):
        SceneConfig(table_edge_prob=0.5, table_edge_dist_m=(0.05, 0.2))
    SceneConfig(table_edge_dist_m=(0.05, 0.2))  # fine while the family is off


@pytest.mark.parametrize("k", [0.8, -0.8])
def test_curved_support_changes_the_floor_depth(k):
    cfg = SimConfig.from_dict({"scene": {"n_objects": [3, 3], "support_curvature": [k, k]}})
    f = generate_frame(1, 9, cfg)
    assert f.scene["params"]["support"]["curvature_per_m"] == k
    p = _world(f, cfg)
    bg = (f.label == 0) & (f.clean > 0)
    sag = k * (p[..., 0] ** 2 + p[..., 1] ** 2)
    np.testing.assert_allclose(p[..., 2][bg], sag[bg], atol=3e-4)  # background is the paraboloid
    assert np.abs(sag[bg]).max() > 0.004  # ... which is visibly not a plane
    flat = generate_frame(1, 9, SimConfig.from_dict({"scene": {"n_objects": [3, 3]}}))
    for o, o0 in zip(f.scene["params"]["objects"], flat.scene["params"]["objects"], strict=True):
        x, y, z = o0["rest_pos_m"]
        assert o["rest_pos_m"][2] == pytest.approx(z + k * (x * x + y * y), abs=2e-6)  # lifted onto the curve


def test_tray_walls_are_raised_background_and_hold_the_objects():
    cfg = SimConfig.from_dict({"scene": {
        "n_objects": [3, 3], "tray_prob": 1.0, "tray_inner_m": [0.16, 0.16],
        "tray_wall_height_m": [0.05, 0.05], "tray_wall_thickness_m": [0.01, 0.01], "camera_height_m": [0.4, 0.4]}})
    for i in range(2):
        f = generate_frame(i, 2, cfg)
        tray = f.scene["params"]["support"]["tray"]
        assert tray["wall_height_m"] == 0.05 and f.scene["params"]["support"]["curvature_per_m"] == 0.0
        z = _world_z(f, cfg)
        bg = (f.label == 0) & (f.clean > 0)
        wall_top = bg & (np.abs(z - 0.05) < 1e-3)
        assert wall_top.sum() > 300  # the wall rims are in view, 5 cm up, labelled background
        assert z[bg].max() < 0.05 + 1e-3 and z[bg].min() > -1e-3
        c, s = np.cos(tray["yaw_rad"]), np.sin(tray["yaw_rad"])
        rot = np.array([[c, -s], [s, c]])  # tray frame -> world
        for o in f.scene["params"]["objects"]:
            local = np.abs(np.asarray(o["rest_pos_m"][:2]) @ rot)
            assert local.max() < 0.08 + 0.01, o["rest_pos_m"]  # resting inside the tray
