"""Frames are a pure function of (seed, index, config): same seed, same frames, in any order."""

from __future__ import annotations

import json

import numpy as np

from edge.io import SIM_EPOCH_NS
from sim.generate import FRAME_PERIOD_NS, SimConfig, generate_frame
from sim.render import ray_grid
from sim.scene import camera_rotation

SMALL = SimConfig.from_dict({"scene": {"n_objects": [2, 5]}})


def _same(a, b) -> bool:
    return (
        np.array_equal(a.depth, b.depth)
        and np.array_equal(a.label, b.label)
        and np.array_equal(a.clean, b.clean)
        and a.scene == b.scene
    )


def test_same_seed_same_frames_and_order_does_not_matter():
    run = [generate_frame(i, 11, SMALL) for i in range(4)]
    alone = generate_frame(3, 11, SMALL)  # regenerated on its own, after other frames
    assert _same(run[3], alone)
    assert _same(generate_frame(0, 11, SMALL), run[0])
    assert not _same(generate_frame(0, 12, SMALL), run[0])
    assert not np.array_equal(run[1].depth, run[2].depth)


def test_frame_contents():
    f = generate_frame(7, 3, SMALL)
    h, w = 171, 224
    assert f.depth.shape == (h, w) and f.depth.dtype == np.float32
    assert f.label.dtype == np.uint8 and set(np.unique(f.label)) <= {0, 1}
    assert f.label.any()
    assert f.stamp_ns == SIM_EPOCH_NS + 7 * FRAME_PERIOD_NS
    valid = f.depth > 0
    assert 0.9 < valid.mean() < 1.0  # some invalid pixels (corners), mostly valid
    cam = f.scene["params"]["camera"]
    r_wc = camera_rotation(cam["yaw_rad"], cam["tilt_x_rad"], cam["tilt_y_rad"])
    world_z = cam["height_m"] + f.clean * (ray_grid(SMALL.camera).dirs @ r_wc.T)[..., 2]
    np.testing.assert_allclose(world_z[f.label == 0], 0.0, atol=2e-4)  # background is the floor
    assert world_z[f.label == 1].mean() > 0.005  # objects stand above it
    # noisy depth stays close to the clean one on valid pixels away from edges
    err = np.abs(f.depth - f.clean)[valid]
    assert np.median(err) < 0.002
    s = json.loads(json.dumps(f.scene))  # JSON-serialisable, as written to /depthseg/scene
    assert s["seed"] == [3, 7] and s["index"] == 7
    assert s["params"]["config_digest"] == SMALL.digest()
    for o in s["params"]["objects"]:
        assert "rest_pos_m" in o and "shape" in o


def test_sensor_and_scene_streams_are_independent():
    import dataclasses

    quiet = dataclasses.replace(SMALL, sensor=dataclasses.replace(SMALL.sensor, noise_scale=(0.1, 0.1)))
    a, b = generate_frame(2, 5, SMALL), generate_frame(2, 5, quiet)
    np.testing.assert_array_equal(a.label, b.label)  # same scene ...
    np.testing.assert_array_equal(a.clean, b.clean)
    assert not np.array_equal(a.depth, b.depth)  # ... different noise
