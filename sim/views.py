"""Several camera poses per settled scene (``scene.views_per_scene``).

Why: drawing the objects and letting MuJoCo settle them is most of a frame's cost (BENCHMARKS.md,
"per-stage costs"), yet the paper used each settled scene for one camera pose only. With
``views_per_scene = V`` frame ``i`` shows scene ``s = i // V`` from view ``v = i % V``:

- the scene (objects, drop, support) comes from the scene stream of ``SeedSequence([seed, s])``,
  i.e. exactly the scene frame ``s`` of a one-view run would settle;
- the camera pose of view ``v`` (height, yaw, tilt; ``scene.camera_*`` ranges) comes from its own
  stream, child 3 of ``SeedSequence([seed, i])``; the sensor stream stays child 1 of it.

So frame ``i`` is still a pure function of ``(seed, i)``: any frame regenerates alone, a resumed or
re-sharded run gives the same frames. A worker keeps the last settled scene (and its Embree BVH)
in memory, so consecutive views of one scene settle it once; a shard that starts in the middle
of a scene settles that scene again (same result, some wasted work): choose ``--shard-frames`` a
multiple of V. ``V = 1`` is the original path, untouched (same frames, same digest).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from sim.scene import SceneConfig, SceneSpec

__all__ = ["VIEW_STREAM", "Settled", "view_streams", "sample_view", "settled_cached", "clear_cache"]

VIEW_STREAM = 3  # child index of SeedSequence([seed, i]) for the camera pose (0 scene, 1 sensor, 2 intrinsics)


@dataclass(eq=False)
class Settled:
    """A scene after the drop, shared by its views (never mutated after settling)."""

    scene: SceneSpec
    pos: np.ndarray
    quat: np.ndarray
    phys: dict[str, Any]
    render_cache: dict[str, Any] = field(default_factory=dict)  # sim.render keeps its Embree scene here


def view_streams(seed: int, index: int, views: int) -> tuple[int, int, np.random.SeedSequence, np.random.SeedSequence]:
    """(scene index, view index, scene stream, camera-pose stream) of frame ``index``."""
    s, v = divmod(int(index), int(views))
    scene_ss = np.random.SeedSequence([int(seed), s]).spawn(1)[0]
    pose_ss = np.random.SeedSequence([int(seed), int(index)], spawn_key=(VIEW_STREAM,))
    return s, v, scene_ss, pose_ss


def _u(rng: np.random.Generator, r: tuple[float, float]) -> float:
    return float(rng.uniform(r[0], r[1])) if r[1] > r[0] else float(r[0])


def sample_view(rng: np.random.Generator, cfg: SceneConfig, scene: SceneSpec) -> SceneSpec:
    """The scene seen from a new camera pose (same draws and ranges as `sim.scene.sample_scene`)."""
    return replace(
        scene,
        camera_height=_u(rng, cfg.camera_height_m),
        yaw=_u(rng, cfg.camera_yaw_rad),
        tilt_x=_u(rng, cfg.camera_tilt_rad),
        tilt_y=_u(rng, cfg.camera_tilt_rad),
    )


_LAST: dict[tuple, Settled] = {}


def settled_cached(key: tuple, settle) -> Settled:
    """The settled scene for ``key`` (seed, scene index, config digest, library id); one kept."""
    hit = _LAST.get(key)
    if hit is None:
        _LAST.clear()
        scene, pos, quat, phys = settle()
        hit = _LAST[key] = Settled(scene, pos, quat, phys)
    return hit


def clear_cache() -> None:
    _LAST.clear()
