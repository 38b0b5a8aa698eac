"""Drop the objects onto the floor with MuJoCo and return where they come to rest.

Why MuJoCo rather than Blender's Bullet (the paper's engine): it is a pip wheel with no
Blender around it, it builds a model from arrays in memory in a few milliseconds (`MjSpec`),
its soft contacts do not explode on deep penetration the way impulse solvers can, it is
deterministic for the same inputs on the same build, and since 3.3 it puts resting bodies to
sleep, which is exactly the "stop early once everything is at rest" we need.

Guards from PITFALLS.md: a pile of meshes can make MuJoCo report "Nan, Inf or huge value in
QACC"; it then resets the state, and a loop on ``data.time`` could run for minutes. So the
step count is capped, ``mjWARN_BADQACC`` (and BADQVEL, BADQPOS) is checked while stepping, and a failed drop raises
`PhysicsUnstable`, which `sim.generate` answers by redrawing the scene from the same frame
seed (deterministic: the redraw continues the frame's random stream).

Collision uses native primitives (box, sphere, cylinder, capsule) where the shape has them,
else the convex hull of a few tens of points (``maxhullvert``); the renderer uses the full
mesh. High friction, as in the paper, keeps objects where they land; torsional and rolling
friction stop spinning cylinders and rolling spheres so scenes settle in ~1-2 s of sim time.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from edge.errors import ConfigError
from sim.scene import SceneSpec, _to_dict, check_fields, check_number, config_from_dict

__all__ = ["PhysicsConfig", "DropResult", "PhysicsUnstable", "drop"]


class PhysicsUnstable(RuntimeError):
    """The simulation diverged (BADQACC, NaN, an object below the floor); redraw the scene."""


@dataclass(frozen=True)
class PhysicsConfig:
    """Drop simulation settings; defaults trade a little contact accuracy for speed.

    The timestep is coarse (10 ms; MuJoCo's default is 2 ms) but no more than half the default
    contact time constant (20 ms), which keeps contacts stable; the floor is a half-space, so
    nothing can tunnel through it. Measured on 193 non-empty default scenes: no unstable drop,
    median deepest penetration 0.3 mm; in ~1 % of scenes two objects that hit each other at
    up to 6 m/s (a 2 m fall) end up overlapping by 5-15 mm, at 6, 8 and 10 ms steps alike.
    Rest: MuJoCo's soft contacts let a settled pile creep (with sleeping off, objects still
    move by a median 2 mm, 90th percentile 16-19 mm, between t = 4 s and 5 s, at 4 and 10 ms
    steps alike); sleeping freezes that. Measured by continuing 45 returned scenes for 1 s with
    sleeping off, sleep tolerance 0.003 leaves a median 5.9 mm / 90th percentile 15.5 mm of
    such motion, 0.01 (20 % cheaper) 7.9 / 25.9 mm: small next to 4-10 cm objects.
    """

    timestep_s: float = 0.01
    max_time_s: float = 3.0  # cap: render whatever pose the objects have by then
    rest_linear_m_s: float = 0.01  # at rest: every body slower than this ...
    rest_angular_rad_s: float = 0.2  # ... and turning slower than this ...
    rest_checks: int = 2  # ... on this many consecutive checks
    check_every: int = 5  # steps between checks
    sleep_tolerance: float = 0.003  # MuJoCo sleeping; 0.01 freezes objects while still sliding (see above)
    friction: tuple[float, float, float] = (1.2, 0.05, 0.02)  # sliding, torsional, rolling (m)
    max_hull_vertices: int = 32
    max_attempts: int = 5  # redraws after an unstable drop before giving up on the frame

    def __post_init__(self) -> None:
        check_fields(self, "physics")
        check_number("physics.timestep_s", self.timestep_s, 1e-4, 0.02)
        check_number("physics.max_time_s", self.max_time_s, 0.0, 60.0)
        check_number("physics.rest_linear_m_s", self.rest_linear_m_s, 0.0)
        check_number("physics.rest_angular_rad_s", self.rest_angular_rad_s, 0.0)
        check_number("physics.rest_checks", self.rest_checks, 1, 1000)
        check_number("physics.check_every", self.check_every, 1, 1000)
        check_number("physics.sleep_tolerance", self.sleep_tolerance, 0.0)
        if len(self.friction) != 3 or any(not (math.isfinite(float(f)) and float(f) >= 0) for f in self.friction):
            raise ConfigError(f"physics.friction must be three non-negative numbers, got {list(self.friction)}")
        check_number("physics.max_hull_vertices", self.max_hull_vertices, 4, 1000)
        check_number("physics.max_attempts", self.max_attempts, 1, 100)

    def to_dict(self) -> dict:
        return _to_dict(self)

    @classmethod
    def from_dict(cls, d: dict | None) -> PhysicsConfig:
        return config_from_dict(cls, d, "physics")


@dataclass
class DropResult:
    pos: np.ndarray  # (n, 3) resting body positions
    quat: np.ndarray  # (n, 4) resting orientations (w, x, y, z)
    steps: int
    time_s: float
    at_rest: bool


def _add_static_boxes(spec, scene: SceneSpec, cfg: PhysicsConfig) -> None:
    """Fixed walls (a tray) on the world body: they collide with objects, never move."""
    import mujoco

    from sim.shapes import _quat_from_matrix

    for half, centre, rot in scene.static_boxes():
        g = spec.worldbody.add_geom()
        g.type = mujoco.mjtGeom.mjGEOM_BOX
        g.size = [float(v) for v in half]
        g.pos = [float(v) for v in centre]
        g.quat = list(_quat_from_matrix(rot))
        g.friction = list(cfg.friction)
        g.condim = 6


def _build(scene: SceneSpec, cfg: PhysicsConfig):
    import mujoco

    spec = mujoco.MjSpec()
    opt = spec.option
    opt.timestep = cfg.timestep_s
    opt.integrator = mujoco.mjtIntegrator.mjINT_IMPLICITFAST
    opt.enableflags |= int(mujoco.mjtEnableBit.mjENBL_SLEEP)
    opt.sleep_tolerance = cfg.sleep_tolerance
    floor = spec.worldbody.add_geom()
    floor.type = mujoco.mjtGeom.mjGEOM_PLANE
    floor.size = [2.0, 2.0, 0.1]
    floor.friction = list(cfg.friction)
    floor.condim = 6
    _add_static_boxes(spec, scene, cfg)
    types = {
        "box": mujoco.mjtGeom.mjGEOM_BOX,
        "sphere": mujoco.mjtGeom.mjGEOM_SPHERE,
        "cylinder": mujoco.mjtGeom.mjGEOM_CYLINDER,
        "capsule": mujoco.mjtGeom.mjGEOM_CAPSULE,
        "ellipsoid": mujoco.mjtGeom.mjGEOM_ELLIPSOID,
    }
    for k, obj in enumerate(scene.objects):
        body = spec.worldbody.add_body()
        body.pos = obj.pos.tolist()
        body.quat = obj.quat.tolist()
        body.add_freejoint()
        for j, part in enumerate(obj.shape.parts):
            g = body.add_geom()
            if part.kind == "hull":
                mesh = spec.add_mesh()
                mesh.name = f"o{k}p{j}"
                mesh.uservert = np.asarray(part.points, dtype=np.float64).ravel().tolist()
                mesh.maxhullvert = int(cfg.max_hull_vertices)
                g.type = mujoco.mjtGeom.mjGEOM_MESH
                g.meshname = mesh.name
            else:
                g.type = types[part.kind]
                size = list(part.size) + [0.0] * (3 - len(part.size))
                g.size = size
            g.pos = list(part.pos)
            g.quat = list(part.quat)
            g.friction = list(cfg.friction)
            g.condim = 6
            g.density = obj.density
    model = spec.compile()
    return model, mujoco.MjData(model)


def drop(scene: SceneSpec, cfg: PhysicsConfig) -> DropResult:
    """Simulate until every object rests (or the time cap); raise PhysicsUnstable on divergence.

    MuJoCo's own warning printer (it writes to stdout) is muted for the duration: the warning
    counters are checked instead, and stdout stays clean for ``--json``.
    """
    import mujoco

    n = len(scene.objects)
    if n == 0:
        return DropResult(np.zeros((0, 3)), np.zeros((0, 4)), 0, 0.0, True)
    previous = mujoco.get_mju_user_warning()
    mujoco.set_mju_user_warning(_mute)
    try:
        return _simulate(scene, cfg, n)
    finally:
        mujoco.set_mju_user_warning(previous)


def _mute(message: str) -> None:
    return None


def _simulate(scene: SceneSpec, cfg: PhysicsConfig, n: int) -> DropResult:
    import mujoco

    try:
        model, data = _build(scene, cfg)
    except ValueError as exc:  # MuJoCo compile errors (e.g. a degenerate hull)
        raise PhysicsUnstable(f"model does not compile: {exc}") from None
    # No body can be at rest before the highest one has had time to land.
    top = max(float(o.pos[2]) for o in scene.objects)
    settle_from = math.sqrt(2.0 * max(top, 0.0) / 9.81)
    max_steps = int(math.ceil(cfg.max_time_s / cfg.timestep_s))
    w = mujoco.mjtWarning
    bad = (w.mjWARN_BADQACC, w.mjWARN_BADQVEL, w.mjWARN_BADQPOS)
    still = 0
    steps = 0
    at_rest = False
    every = int(cfg.check_every)
    while steps < max_steps:
        mujoco.mj_step(model, data, nstep=every)
        steps += every
        for b in bad:
            if data.warning[b].number > 0:
                raise PhysicsUnstable(f"{b.name} after {steps} steps")
        if data.time < settle_from:
            continue
        if data.ntree_awake == 0:
            at_rest = True
            break
        v = data.qvel.reshape(n, 6)
        if np.abs(v[:, :3]).max() < cfg.rest_linear_m_s and np.abs(v[:, 3:]).max() < cfg.rest_angular_rad_s:
            still += 1
            if still >= cfg.rest_checks:
                at_rest = True
                break
        else:
            still = 0
    pos = data.xpos[1:].copy()
    quat = data.xquat[1:].copy()
    if not (np.all(np.isfinite(pos)) and np.all(np.isfinite(quat))):
        raise PhysicsUnstable("non-finite body pose")
    if pos[:, 2].min() < -0.05:
        raise PhysicsUnstable("an object ended below the floor")
    return DropResult(pos, quat, steps, float(data.time), at_rest)
