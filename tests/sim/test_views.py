"""``scene.views_per_scene``: several camera poses per settled scene, frame i still a function of (seed, i)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from edge.errors import ConfigError
from sim.generate import SimConfig, generate_frame
from sim.views import clear_cache

ONE = SimConfig.from_dict({"scene": {"n_objects": [2, 5], "views_per_scene": 1}})
FOUR = SimConfig.from_dict({"scene": {"n_objects": [2, 5], "views_per_scene": 4}})


def _same(a, b) -> bool:
    return (np.array_equal(a.depth, b.depth) and np.array_equal(a.label, b.label)
            and np.array_equal(a.clean, b.clean) and a.scene == b.scene)


def test_default_is_four_views_and_one_view_data_keep_their_digest():
    assert SimConfig().scene.views_per_scene == 4
    old = SimConfig.from_dict({"scene": {"n_objects": [2, 5]}})
    # a one-view config reads back as one view, and its digest is the one it had before views existed
    assert SimConfig.from_dict(ONE.to_dict()).scene.views_per_scene == 1
    assert "views_per_scene" not in ONE.to_dict(for_digest=True)["scene"]
    assert old.scene.views_per_scene == 4 and old.digest() != ONE.digest()
    assert "view" not in generate_frame(0, 1, ONE).scene["params"]


def test_views_share_the_settled_scene_and_differ_in_pose():
    frames = [generate_frame(i, 7, FOUR) for i in range(5)]
    p = [f.scene["params"] for f in frames]
    assert [q["view"]["scene_index"] for q in p] == [0, 0, 0, 0, 1]
    assert [q["view"]["view"] for q in p] == [0, 1, 2, 3, 0]
    rest = [[o["rest_pos_m"] for o in q["objects"]] for q in p]
    assert rest[0] == rest[1] == rest[2] == rest[3] != rest[4]
    cams = {json.dumps(q["camera"], sort_keys=True) for q in p[:4]}
    assert len(cams) == 4
    assert not np.array_equal(frames[0].depth, frames[1].depth)


def test_a_view_regenerates_alone_and_in_any_order():
    seq = [generate_frame(i, 7, FOUR) for i in range(4)]
    clear_cache()
    assert _same(generate_frame(2, 7, FOUR), seq[2])  # cold cache, mid-scene
    assert _same(generate_frame(0, 7, FOUR), seq[0])
    clear_cache()
    assert _same(generate_frame(3, 7, FOUR), seq[3])
    assert not _same(generate_frame(3, 8, FOUR), seq[3])


def test_scene_of_a_view_is_the_one_view_scene():
    a, b = generate_frame(6, 7, FOUR), generate_frame(1, 7, ONE)  # scene 6 // 4 == 1
    assert [o["rest_pos_m"] for o in a.scene["params"]["objects"]] == [o["rest_pos_m"] for o in b.scene["params"]["objects"]]


@pytest.mark.parametrize("bad", [0, -1, 1.5, True, "2"])
def test_bad_views_per_scene(bad):
    with pytest.raises(ConfigError, match="views_per_scene"):
        SimConfig.from_dict({"scene": {"views_per_scene": bad}})
