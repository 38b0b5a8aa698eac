"""One labelled frame from (seed, index): scene -> drop -> ray cast -> sensor model.

Why per-frame seeding: frame i draws everything from ``np.random.SeedSequence([seed, i])``,
so any frame can be regenerated alone (to inspect a bad one, or to resume a killed run in any
order on any number of workers) and the same seed always gives the same frames. The sequence
is split into two streams, scene and sensor, so that changing a sensor setting does not
change the scenes, and vice versa. A drop that goes unstable is redrawn from the scene stream
(still deterministic); after ``physics.max_attempts`` failures the frame falls back to an
empty table rather than killing a long run, and its scene JSON says so.
"""

from __future__ import annotations

import hashlib
import json
import typing
from dataclasses import dataclass, field, fields, replace
from functools import lru_cache
from typing import Any

import numpy as np

from edge.errors import ConfigError
from edge.io import SIM_EPOCH_NS
from edge.meta import SensorSpec
from sim.physics import PhysicsConfig, PhysicsUnstable, drop
from sim.render import Camera, ray_grid, render
from sim.scene import (
    SceneConfig,
    SceneSpec,
    _short_keys,
    check_fields,
    check_number,
    check_value,
    quat_to_matrix,
    sample_scene,
)
from sim.sensor import SensorConfig, apply_sensor, draw_frame_params
from sim.shapes import MeshLibrary

__all__ = ["SimConfig", "SimFrame", "generate_frame", "FRAME_PERIOD_NS"]

FRAME_PERIOD_NS = 22_222_222  # 45 fps: Royale MODE_5_45FPS_500, the wrist-camera use case
# fx, fy, cx, cy fitted to the points of the shared real capture (depthseg-sim import ply)
REAL_PICO_FLEXX_K = (202.0, 204.8, 115.8, 88.0)
MAX_RENDER_THREADS = 256


@dataclass(frozen=True)
class SimConfig:
    """Everything a frame depends on besides (seed, index) and the mesh library."""

    scene: SceneConfig = field(default_factory=SceneConfig)
    physics: PhysicsConfig = field(default_factory=PhysicsConfig)
    sensor: SensorConfig = field(default_factory=SensorConfig)
    camera: Camera = field(default_factory=lambda: Camera.from_spec(SensorSpec()))
    supersample_edges: bool = True
    render_threads: int = 1  # one per worker process: the workers are the parallelism
    # Per-frame intrinsics: 0 = always ``camera``; N > 0 = one of N cameras spaced evenly from
    # ``camera`` to ``intrinsics_to`` (default: the real pico flexx calibration fitted on the shared
    # capture). A fixed set keeps the ray grids cached per worker.
    intrinsics_steps: int = 0
    intrinsics_to: tuple[float, float, float, float] = REAL_PICO_FLEXX_K
    # Labels: 0 = an object pixel is object wherever the ray hits it (the default); h > 0 = the
    # parts of objects lower than h metres above the table are table, as a geometric labelling
    # rule calls them; objects entirely below h stay object (`sim.render.RenderResult.label_above`).
    label_min_height_m: float = 0.0

    def camera_for(self, rng: np.random.Generator | None) -> Camera:
        """The camera of one frame (drawn from ``rng`` only when ``intrinsics_steps`` > 0)."""
        if self.intrinsics_steps <= 0 or rng is None:
            return self.camera
        t = int(rng.integers(0, self.intrinsics_steps)) / max(self.intrinsics_steps - 1, 1)
        a = np.array(self.camera.intrinsics)
        fx, fy, cx, cy = (a + t * (np.array(self.intrinsics_to) - a)).round(4).tolist()
        return replace(self.camera, fx=fx, fy=fy, cx=cx, cy=cy)

    def to_dict(self, for_digest: bool = False) -> dict[str, Any]:
        """The configuration as JSON; ``for_digest`` leaves out keys at their pre-existing neutral values."""
        cam = self.camera
        return {
            "scene": self.scene.to_dict(for_digest),
            "physics": self.physics.to_dict(),
            "sensor": self.sensor.to_dict(),
            "camera": {
                "width": cam.width,
                "height": cam.height,
                "fx": cam.fx,
                "fy": cam.fy,
                "cx": cam.cx,
                "cy": cam.cy,
                "distortion": list(cam.distortion),
            },
            "supersample_edges": self.supersample_edges,
            "render_threads": self.render_threads,
            **(
                {"intrinsics_steps": self.intrinsics_steps, "intrinsics_to": list(self.intrinsics_to)}
                if self.intrinsics_steps
                else {}
            ),
            **({"label_min_height_m": self.label_min_height_m} if self.label_min_height_m else {}),
        }

    def __post_init__(self) -> None:
        check_fields(self, "config")
        check_number("config.render_threads", self.render_threads, 1, MAX_RENDER_THREADS)
        check_number("config.intrinsics_steps", self.intrinsics_steps, 0, 64)
        check_number("config.label_min_height_m", self.label_min_height_m, 0.0, 0.1)
        if min(self.intrinsics_to) <= 0:
            raise ConfigError(
                f"config.intrinsics_to must be four positive numbers fx, fy, cx, cy; got {list(self.intrinsics_to)}"
            )

    @classmethod
    def from_dict(cls, d: dict[str, Any] | None) -> SimConfig:
        """Build from JSON (e.g. ``--config``); missing sections keep their defaults.

        Every value is checked by type and range (`sim.scene.check_value`): one `ConfigError`
        naming the key, never a silent conversion (``"no"`` is not false, ``"05"`` not [0, 5]).
        """
        if d is None:
            d = {}
        if not isinstance(d, dict):
            raise ConfigError(f"a simulator config must be a JSON object {{\"scene\": ...}}, got {type(d).__name__}")
        d = dict(d)
        known = {"scene", "physics", "sensor", "camera", "supersample_edges", "render_threads", "intrinsics_steps",
                 "intrinsics_to", "label_min_height_m"}
        unknown = sorted(set(d) - known)
        if unknown:
            raise ConfigError(f"unknown config sections {_short_keys(unknown)}; valid: {sorted(known)}")
        cam = d.get("camera")
        cam = {} if cam is None else cam
        if not isinstance(cam, dict):
            raise ConfigError(f"config section 'camera' must be an object, got {type(cam).__name__}")
        base = Camera.from_spec(SensorSpec())
        ckeys = {f.name for f in fields(Camera)}
        bad = sorted(set(cam) - ckeys)
        if bad:
            raise ConfigError(f"unknown camera keys {_short_keys(bad)}; valid keys: {sorted(ckeys)}")
        hints = typing.get_type_hints(Camera)
        for k, v in cam.items():
            check_value(f"camera.{k}", v, hints[k])
        camera = Camera(
            width=int(cam.get("width", base.width)),
            height=int(cam.get("height", base.height)),
            fx=float(cam.get("fx", base.fx)),
            fy=float(cam.get("fy", base.fy)),
            cx=float(cam.get("cx", base.cx)),
            cy=float(cam.get("cy", base.cy)),
            distortion=tuple(float(v) for v in cam.get("distortion", ())),
        )
        steps = d.get("intrinsics_steps", 0)
        check_value("config.intrinsics_steps", steps, int)
        k_to = d.get("intrinsics_to", REAL_PICO_FLEXX_K)
        check_value("config.intrinsics_to", k_to, tuple[float, float, float, float])
        return cls(
            intrinsics_steps=int(steps),
            intrinsics_to=tuple(float(v) for v in k_to),
            scene=SceneConfig.from_dict(d.get("scene")),
            physics=PhysicsConfig.from_dict(d.get("physics")),
            sensor=SensorConfig.from_dict(d.get("sensor")),
            camera=camera,
            supersample_edges=d.get("supersample_edges", True),
            render_threads=d.get("render_threads", 1),
            label_min_height_m=d.get("label_min_height_m", 0.0),
        )

    def digest(self) -> str:
        """Short hash of the configuration: frames of one output directory must share it."""
        return _digest(self)


@lru_cache(maxsize=16)
def _digest(config: SimConfig) -> str:
    return hashlib.sha256(json.dumps(config.to_dict(for_digest=True), sort_keys=True).encode()).hexdigest()[:16]


@dataclass
class SimFrame:
    index: int
    stamp_ns: int
    depth: np.ndarray  # float32 (H, W) Z in metres, 0 = invalid
    label: np.ndarray  # uint8 (H, W) 1 = object
    clean: np.ndarray  # float32 (H, W) noise-free Z
    intrinsics: tuple[float, float, float, float]
    distortion: tuple[float, ...]
    scene: dict[str, Any]


def _settle(
    rng: np.random.Generator, config: SimConfig, library: MeshLibrary | None
) -> tuple[SceneSpec, np.ndarray, np.ndarray, dict[str, Any]]:
    last = ""
    for attempt in range(int(config.physics.max_attempts)):
        scene = sample_scene(rng, config.scene, library)
        try:
            res = drop(scene, config.physics)
        except PhysicsUnstable as exc:
            last = str(exc)
            continue
        info = {"attempts": attempt + 1, "steps": res.steps, "time_s": round(res.time_s, 4), "at_rest": res.at_rest}
        return scene, scene.rest_on_support(res.pos), res.quat, info
    scene = sample_scene(rng, replace(config.scene, n_objects=(0, 0)), None)
    info = {"attempts": int(config.physics.max_attempts), "fallback": "empty scene", "last_error": last}
    return scene, np.zeros((0, 3)), np.zeros((0, 4)), info


def _view(index: int, seed: int, config: SimConfig, library: MeshLibrary | None):
    """Scene ``index // V`` (settled once per worker) seen from the pose of view ``index % V``."""
    from sim.views import sample_view, settled_cached, view_streams

    s, v, scene_ss, pose_ss = view_streams(seed, index, config.scene.views_per_scene)
    lib_key = None if library is None else tuple(str(p) for p in library.paths)
    st = settled_cached((int(seed), s, config.digest(), lib_key),
                        lambda: _settle(np.random.default_rng(scene_ss), config, library))
    scene = sample_view(np.random.default_rng(pose_ss), config.scene, st.scene)
    info = {"scene_index": s, "view": v, "views_per_scene": config.scene.views_per_scene}
    return scene, st.pos, st.quat, st.phys, st.render_cache, info


def generate_frame(
    index: int, seed: int, config: SimConfig | None = None, library: MeshLibrary | None = None
) -> SimFrame:
    """Frame ``index`` of the run with ``seed``: identical whenever and wherever it is made."""
    config = config or SimConfig()
    ss = np.random.SeedSequence([int(seed), int(index)])
    scene_ss, sensor_ss, camera_ss = ss.spawn(3)  # the first two as before: same frames
    sensor_rng = np.random.default_rng(sensor_ss)

    views = config.scene.views_per_scene
    render_cache = None
    if views == 1:
        scene, pos, quat, phys = _settle(np.random.default_rng(scene_ss), config, library)
    else:  # several camera poses per settled scene (sim.views)
        scene, pos, quat, phys, render_cache, view = _view(index, seed, config, library)
    meshes = []
    for k, obj in enumerate(scene.objects):
        rot = quat_to_matrix(quat[k])
        meshes.append(((obj.shape.vertices.astype(np.float64) @ rot.T + pos[k]).astype(np.float32), obj.shape.triangles))
    cam = config.camera_for(np.random.default_rng(camera_ss) if config.intrinsics_steps else None)
    rr = render(
        meshes,
        cam,
        scene.camera_rotation,
        scene.camera_position,
        supersample=config.supersample_edges and config.sensor.mixed_pixels,
        threads=config.render_threads,
        support=scene.render_support(),
        background=scene.background_meshes(),
        cache=render_cache,
    )
    draw = draw_frame_params(sensor_rng, config.sensor, len(scene.objects))
    out = apply_sensor(rr, ray_grid(cam), cam.fx, scene.camera_height, draw, config.sensor, sensor_rng)

    params = scene.to_params()
    for k, o in enumerate(params["objects"]):
        o["rest_pos_m"] = pos[k].round(6).tolist()
        o["rest_quat"] = quat[k].round(6).tolist()
    params["physics"] = phys
    params["sensor"] = draw.to_params()
    params["config_digest"] = config.digest()
    if views > 1:
        params["view"] = view
    label = rr.label_above(config.label_min_height_m)
    return SimFrame(
        index=int(index),
        stamp_ns=SIM_EPOCH_NS + int(index) * FRAME_PERIOD_NS,
        depth=out.depth,
        label=label,
        clean=rr.z,
        intrinsics=cam.intrinsics,
        distortion=tuple(cam.distortion),
        scene={"index": int(index), "seed": [int(seed), int(index)], "params": params},
    )
