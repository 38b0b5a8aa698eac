"""MuJoCo drop: objects end up resting on the floor (or on each other), caps and guards hold."""

from __future__ import annotations

import numpy as np
import pytest

from sim import generate as gen
from sim.physics import PhysicsConfig, PhysicsUnstable, drop
from sim.scene import ObjectSpec, SceneConfig, SceneSpec, euler_to_quat, quat_to_matrix, sample_scene
from sim.shapes import make_shape


def _scene(objects):
    return SceneSpec(0.3, (0.0, 0.0), 0.0, 0.0, 0.0, objects)


def _lowest(obj, pos, quat):
    return float((obj.shape.vertices.astype(float) @ quat_to_matrix(quat).T + pos)[:, 2].min())


def test_box_comes_to_rest_on_the_floor():
    shape = make_shape("box", np.random.default_rng(1), 0.06, 0.02)
    obj = ObjectSpec(shape, np.array([0.0, 0.0, 0.2]), euler_to_quat(0.3, 0.2, 0.1), 500.0, (0.3, 0.2, 0.1))
    res = drop(_scene([obj]), PhysicsConfig())
    assert res.at_rest and res.time_s < PhysicsConfig().max_time_s
    assert _lowest(obj, res.pos[0], res.quat[0]) == pytest.approx(0.0, abs=0.002)
    # a box at rest lies on a face: its lowest corner's face is horizontal, its top is at a side length
    top = float((shape.vertices.astype(float) @ quat_to_matrix(res.quat[0]).T + res.pos[0])[:, 2].max())
    assert any(abs(top - s) < 0.002 for s in shape.extents)


def test_default_scenes_settle_with_every_object_supported():
    cfg, pc = SceneConfig(), PhysicsConfig()
    for i in (2, 5):
        scene = sample_scene(np.random.default_rng(i), cfg)
        assert len(scene.objects) >= 5
        res = drop(scene, pc)
        lows = [_lowest(o, res.pos[k], res.quat[k]) for k, o in enumerate(scene.objects)]
        assert min(lows) > -0.004  # nothing sinks into the floor
        # released up to 2 m high; after the drop every object rests low in a pile
        assert max(lows) < 0.15
        assert max(lows) < max(o.pos[2] for o in scene.objects)


def test_time_cap_stops_an_unsettled_scene():
    scene = sample_scene(np.random.default_rng(2), SceneConfig(n_objects=(6, 6)))
    res = drop(scene, PhysicsConfig(max_time_s=0.2))
    assert not res.at_rest and res.time_s <= 0.2 + 0.05


def test_unstable_drops_are_redrawn_deterministically(monkeypatch):
    calls = {"n": 0}
    real_drop = gen.drop

    def flaky(scene, cfg):
        calls["n"] += 1
        if calls["n"] == 1:
            raise PhysicsUnstable("BADQACC (simulated)")
        return real_drop(scene, cfg)

    monkeypatch.setattr(gen, "drop", flaky)
    one = gen.SimConfig.from_dict({"scene": {"views_per_scene": 1}})  # no settled-scene cache between calls
    a = gen.generate_frame(4, 9, one)
    assert a.scene["params"]["physics"]["attempts"] == 2
    calls["n"] = 0
    b = gen.generate_frame(4, 9, one)
    np.testing.assert_array_equal(a.depth, b.depth)

    def always(scene, cfg):
        raise PhysicsUnstable("BADQACC (simulated)")

    monkeypatch.setattr(gen, "drop", always)
    c = gen.generate_frame(4, 9, one)
    assert c.scene["params"]["physics"]["fallback"] == "empty scene"
    assert c.label.sum() == 0 and c.scene["params"]["objects"] == []


def test_real_divergence_is_caught_silently(monkeypatch, capfd):
    import mujoco

    from sim import physics

    build = physics._build

    def exploding(scene, cfg):
        model, data = build(scene, cfg)
        data.qvel[:] = 1e300  # MuJoCo flags this as unstable on the first step
        return model, data

    monkeypatch.setattr(physics, "_build", exploding)
    scene = sample_scene(np.random.default_rng(2), SceneConfig(n_objects=(3, 3)))
    with pytest.raises(PhysicsUnstable, match="mjWARN_BAD"):
        drop(scene, PhysicsConfig())
    assert capfd.readouterr().out == ""  # MuJoCo's warning printer was muted (stdout stays JSON-clean)
    assert mujoco.get_mju_user_warning() is None  # and restored afterwards
