"""Ray-cast the pico flexx: per-pixel range, Z, surface angle and object id.

Why ray casting (open3d's Embree-backed RaycastingScene) and not a rasteriser: a ToF pixel
*is* a ray (SENSOR.md: it measures radial distance along its ray), distortion is handled by
giving each pixel its own ray direction, object ids come for free (the binary label), and the
surface normal at the hit gives the incidence angle the amplitude model needs. No GPU, no
window system, and a 224 x 171 frame is only 38,304 rays.

Camera model: intrinsics are a parameter (`Camera`); the default is `edge.meta.SensorSpec`'s
pinhole from the datasheet's 62 x 45 deg field of view, as BlenSor built it. With a plumb_bob
distortion, each pixel of the (distorted) image grid gets the undistorted ray through it, so Z
is reported on the distorted grid as Royale does. Ray directions have z = 1 in the camera
frame, so the hit distance *is* Z and the radial range is r = Z * |ray|.

Mixed pixels: a real pixel integrates light over its footprint; where that footprint straddles
a depth edge it returns a blend of both surfaces (SENSOR.md "flying pixels"). Casting every
pixel 4x would quadruple the cost, so only pixels next to an id change or a range jump are
supersampled (a rotated-grid pattern of sub-rays); the sensor model blends those samples.

Speed: the floor is the plane z = 0 and is intersected analytically; only the rays inside the
projected bounding boxes of the objects go to Embree (typically a third of the frame).

Supports other than the infinite plane (scene families where a floor-plane fit fails): a
`Support` makes the table gently curved (z = k (x^2 + y^2), an analytic ray-paraboloid hit)
and/or gives it a straight edge beyond which rays fall to a lower room floor z = -drop; both
are background. Background meshes (tray walls) are cast with the objects but get FLOOR_ID,
so they are labelled 0 like the table they stand on.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from edge.errors import ConfigError
from edge.meta import SensorSpec

__all__ = ["Camera", "RayGrid", "RenderResult", "Support", "ray_grid", "render", "FLOOR_ID", "NO_HIT"]

FLOOR_ID = 0  # ids: 0 floor, k + 1 object k, NO_HIT nothing
NO_HIT = -1
# Largest frame the simulator renders: a few float64 arrays of (H, W, 3) per frame and worker must
# stay far below 1 GB (a pico flexx frame has 38,304 pixels; 1024 x 1024 is ~27x that).
MAX_CAMERA_PIXELS = 1024 * 1024

# Rotated-grid supersampling offsets (pixels), 4 samples: each row and column sampled once.
_RGSS = np.array([[-0.375, -0.125], [0.125, -0.375], [0.375, 0.125], [-0.125, 0.375]])


@dataclass(frozen=True)
class Camera:
    """Pinhole (+ optional plumb_bob) camera; pixel centres at integer coordinates."""

    width: int = 224
    height: int = 171
    fx: float = SensorSpec().fx
    fy: float = SensorSpec().fy
    cx: float = SensorSpec().cx
    cy: float = SensorSpec().cy
    distortion: tuple[float, ...] = ()

    def __post_init__(self) -> None:
        from sim.scene import check_fields

        check_fields(self, "camera")  # whole sizes, finite intrinsics (no NaN, no Infinity)
        if self.width < 2 or self.height < 2:
            raise ConfigError(f"camera size {self.width}x{self.height} is too small")
        if self.width * self.height > MAX_CAMERA_PIXELS:
            raise ConfigError(
                f"camera size {self.width}x{self.height} is above the simulator's limit of {MAX_CAMERA_PIXELS} pixels "
                "(a pico flexx frame is 224x171)"
            )
        for name in ("fx", "fy"):
            if not float(getattr(self, name)) > 0:
                raise ConfigError(f"camera.{name} must be positive, got {getattr(self, name)}")
        if len(self.distortion) not in (0, 4, 5, 8):
            raise ConfigError(
                f"camera.distortion has {len(self.distortion)} values; plumb_bob takes 5 (k1 k2 p1 p2 k3)"
            )

    @classmethod
    def from_spec(cls, s: SensorSpec) -> Camera:
        return cls(s.width, s.height, s.fx, s.fy, s.cx, s.cy, tuple(s.distortion))

    @property
    def intrinsics(self) -> tuple[float, float, float, float]:
        return (self.fx, self.fy, self.cx, self.cy)


@dataclass(frozen=True, eq=False)
class RayGrid:
    dirs: np.ndarray  # (H, W, 3) float32, camera frame, z = 1
    norm: np.ndarray  # (H, W) float32 |dirs|
    sub_dirs: np.ndarray  # (H, W, S, 3) float32 supersampling rays, z = 1


def _normalised(cam: Camera, u: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    if not any(cam.distortion):
        return (u - cam.cx) / cam.fx, (v - cam.cy) / cam.fy
    import cv2

    k = np.array([[cam.fx, 0, cam.cx], [0, cam.fy, cam.cy], [0, 0, 1]], dtype=np.float64)
    pts = np.stack([u.ravel(), v.ravel()], -1).astype(np.float64).reshape(-1, 1, 2)
    crit = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 50, 1e-9)
    und = cv2.undistortPoints(pts, k, np.asarray(cam.distortion, np.float64), None, None, None, crit).reshape(-1, 2)
    return und[:, 0].reshape(u.shape), und[:, 1].reshape(u.shape)


@lru_cache(maxsize=16)
def ray_grid(cam: Camera) -> RayGrid:
    """Per-pixel ray directions (cached per camera: computed once per worker)."""
    v, u = np.mgrid[0 : cam.height, 0 : cam.width].astype(np.float64)
    xn, yn = _normalised(cam, u, v)
    dirs = np.stack([xn, yn, np.ones_like(xn)], -1)
    su = u[..., None] + _RGSS[:, 0]
    sv = v[..., None] + _RGSS[:, 1]
    sx, sy = _normalised(cam, su, sv)
    sub = np.stack([sx, sy, np.ones_like(sx)], -1)
    return RayGrid(dirs.astype(np.float32), np.linalg.norm(dirs, axis=-1).astype(np.float32), sub.astype(np.float32))


@dataclass(eq=False)
class RenderResult:
    z: np.ndarray  # (H, W) float32 clean Z along the optical axis, metres (0 where nothing hit)
    r: np.ndarray  # (H, W) float32 radial range
    ids: np.ndarray  # (H, W) int32: FLOOR_ID, k + 1 for object k, NO_HIT
    cos_inc: np.ndarray  # (H, W) float32 |cos| of the angle between ray and surface normal
    height: np.ndarray  # (H, W) float32 height of the hit point above the floor
    edge: np.ndarray  # (E,) flat indices of supersampled (edge) pixels
    sub_r: np.ndarray  # (E, S) radial range of each sub-ray
    sub_ids: np.ndarray  # (E, S)
    sub_cos: np.ndarray  # (E, S)
    above_support: np.ndarray | None = None  # (H, W) float32 height above the table top under the hit (None: = height)

    @property
    def label(self) -> np.ndarray:
        """1 where the pixel-centre ray hits an object, else 0 (mono8)."""
        return (self.ids > FLOOR_ID).astype(np.uint8)

    def label_above(self, min_height_m: float) -> np.ndarray:
        """`label`, with the parts of objects lower than ``min_height_m`` above the table called table.

        Why: labels of real frames made by a geometric rule ("object = more than 10 mm above the
        floor plane") call the base of every object table; this gives simulated frames that
        meaning, to measure what training on it does. An object whose every visible pixel lies
        below the line (a thin plate, a coin) stays object whole, as the thin-object family asks.

        Args:
            min_height_m: the line in metres above the table top under each hit; 0 = `label`.
        """
        lab = self.ids > FLOOR_ID
        if min_height_m <= 0 or not lab.any():
            return lab.astype(np.uint8)
        above = self.height if self.above_support is None else self.above_support
        top = np.full(int(self.ids.max()) + 1, -np.inf)
        np.maximum.at(top, self.ids[lab], above[lab])  # highest visible point of each object
        low = lab & (above < min_height_m) & (top[np.maximum(self.ids, 0)] >= min_height_m)
        return (lab & ~low).astype(np.uint8)


def _cast(scene, origin: np.ndarray, dirs: np.ndarray, norm: np.ndarray, threads: int):
    """Hit distance (in units of the z = 1 direction, i.e. Z), object index or NO_HIT, |cos|."""
    import open3d as o3d

    rays = np.empty((len(dirs), 6), dtype=np.float32)
    rays[:, :3] = origin
    rays[:, 3:] = dirs
    res = scene.cast_rays(o3d.core.Tensor(rays), nthreads=threads)
    t = res["t_hit"].numpy()
    hit = np.isfinite(t)
    gid = np.where(hit, res["geometry_ids"].numpy().astype(np.int64), NO_HIT).astype(np.int32)
    nrm = res["primitive_normals"].numpy()
    cos = np.abs(np.einsum("ij,ij->i", nrm, dirs)) / norm
    return np.where(hit, t, np.inf).astype(np.float32), gid, cos.astype(np.float32)


def _floor(origin: np.ndarray, dirs: np.ndarray, norm: np.ndarray):
    """Analytic hit on the floor plane z = 0 (cheaper than casting it): t, ids, |cos|."""
    dz = dirs[:, 2]
    down = dz < -1e-9
    with np.errstate(divide="ignore"):
        t = np.where(down, -float(origin[2]) / np.where(down, dz, -1.0), np.inf).astype(np.float32)
    ids = np.where(down, FLOOR_ID, NO_HIT).astype(np.int32)
    return t, ids, (np.abs(dz) / norm).astype(np.float32)


@dataclass(frozen=True)
class Support:
    """The table, when it is not the infinite plane z = 0 (all of it is background).

    ``curvature`` k: the table top is z = k (x^2 + y^2) (k > 0 a shallow bowl, k < 0 a dome).
    ``edge_normal`` (unit, xy) and ``edge_dist``: the table ends where p . n > edge_dist; there
    rays continue to the room floor z = -``drop``. The camera must be above the table (p . n <
    edge_dist at the camera), so the table's side face, which faces away from it, is never seen.
    """

    curvature: float = 0.0
    edge_normal: tuple[float, float] | None = None
    edge_dist: float = 0.0
    drop: float = 0.0


def _top_hit(origin: np.ndarray, d: np.ndarray, k: float) -> tuple[np.ndarray, np.ndarray]:
    """First hit t (inf: none) of rays with the table top z = k (x^2 + y^2), and its normals."""
    ox, oy, oz = (float(c) for c in origin)
    if k == 0.0:
        dz = d[:, 2]
        down = dz < -1e-12
        with np.errstate(divide="ignore", invalid="ignore"):
            t = np.where(down, -oz / np.where(down, dz, -1.0), np.inf)
        return t, np.broadcast_to(np.array([0.0, 0.0, 1.0]), d.shape)
    a = k * (d[:, 0] ** 2 + d[:, 1] ** 2)
    b = 2 * k * (ox * d[:, 0] + oy * d[:, 1]) - d[:, 2]
    c = k * (ox * ox + oy * oy) - oz
    disc = b * b - 4 * a * c
    ok = disc >= 0
    q = -0.5 * (b + np.copysign(np.sqrt(np.where(ok, disc, 0.0)), b))
    with np.errstate(divide="ignore", invalid="ignore"):
        r1 = np.where(np.abs(a) > 1e-15, q / a, np.inf)
        r2 = np.where(np.abs(q) > 1e-15, c / q, np.inf)
    r1 = np.where(ok & (r1 > 1e-9), r1, np.inf)
    r2 = np.where(ok & (r2 > 1e-9), r2, np.inf)
    t = np.minimum(r1, r2)
    tt = np.where(np.isfinite(t), t, 0.0)
    px, py = ox + tt * d[:, 0], oy + tt * d[:, 1]
    n = np.stack([-2 * k * px, -2 * k * py, np.ones_like(px)], -1)
    return t, n


def _support(origin: np.ndarray, dirs: np.ndarray, norm: np.ndarray, sup: Support | None):
    """Like `_floor` (t, ids, |cos|) for a curved and/or edged table; `_floor` when None."""
    if sup is None:
        return _floor(origin, dirs, norm)
    d = dirs.astype(np.float64)
    t, n = _top_hit(origin, d, float(sup.curvature))
    cos = np.abs(np.einsum("ij,ij->i", n, d)) / (np.linalg.norm(n, axis=1) * norm)
    if sup.edge_normal is not None:
        ex, ey = sup.edge_normal
        tt = np.where(np.isfinite(t), t, 0.0)
        side = (origin[0] + tt * d[:, 0]) * ex + (origin[1] + tt * d[:, 1]) * ey
        off = ~np.isfinite(t) | (side > sup.edge_dist)  # missed the table or hit beyond its edge
        down = d[:, 2] < -1e-12
        with np.errstate(divide="ignore", invalid="ignore"):
            t_low = np.where(down, -(float(origin[2]) + sup.drop) / np.where(down, d[:, 2], -1.0), np.inf)
        t = np.where(off, t_low, t)
        cos = np.where(off, np.abs(d[:, 2]) / norm, cos)
    ids = np.where(np.isfinite(t), FLOOR_ID, NO_HIT).astype(np.int32)
    return t.astype(np.float32), ids, cos.astype(np.float32)


def _candidates(meshes, cam: Camera, grid: RayGrid, rot: np.ndarray, origin: np.ndarray) -> np.ndarray:
    """Pixels whose ray may hit an object: inside the bounding box of its projected vertices.

    Conservative: a mesh's image lies inside the convex hull of its projected vertices when it
    is entirely in front of the camera; an object reaching behind the camera marks every pixel.
    """
    h, w = cam.height, cam.width
    mask = np.zeros((h, w), dtype=bool)
    pinhole = not any(cam.distortion)
    gx, gy = grid.dirs[..., 0], grid.dirs[..., 1]
    for v, _t in meshes:
        pc = (np.asarray(v, np.float64) - origin) @ rot  # camera coordinates
        zc = pc[:, 2]
        if zc.min() <= 1e-3:
            mask[:] = True
            break
        xn, yn = pc[:, 0] / zc, pc[:, 1] / zc
        if pinhole:
            u0 = int(np.floor(cam.fx * xn.min() + cam.cx)) - 1
            u1 = int(np.ceil(cam.fx * xn.max() + cam.cx)) + 2
            v0 = int(np.floor(cam.fy * yn.min() + cam.cy)) - 1
            v1 = int(np.ceil(cam.fy * yn.max() + cam.cy)) + 2
            if u1 > 0 and v1 > 0 and u0 < w and v0 < h:
                mask[max(v0, 0) : v1, max(u0, 0) : u1] = True
        else:
            px = 1.0 / min(cam.fx, cam.fy)  # one pixel of margin in normalised units
            mask |= (gx >= xn.min() - px) & (gx <= xn.max() + px) & (gy >= yn.min() - px) & (gy <= yn.max() + px)
    return np.flatnonzero(mask)


def _mesh_ids(gid: np.ndarray, n_obj: int) -> np.ndarray:
    """Pixel ids of Embree geometry ids: object k -> k + 1, background meshes -> FLOOR_ID."""
    return np.where(gid < n_obj, gid + 1, FLOOR_ID).astype(np.int32)


def render(
    meshes: list[tuple[np.ndarray, np.ndarray]],
    cam: Camera,
    rotation: np.ndarray,
    position: np.ndarray,
    edge_jump_m: float = 0.004,
    supersample: bool = True,
    threads: int = 1,
    support: Support | None = None,
    background: list[tuple[np.ndarray, np.ndarray]] | tuple = (),
    cache: dict | None = None,
) -> RenderResult:
    """Cast one frame. ``meshes`` are (vertices, triangles) in world coordinates, floor at z = 0.

    ``rotation`` is world-from-camera, ``position`` the camera centre in the world. The floor
    (or the ``support``) is intersected analytically; only rays that may meet a mesh are cast.
    ``background`` meshes (tray walls) are cast like objects but labelled FLOOR_ID.
    ``cache``: a dict owned by the caller for one fixed set of meshes (several views of one
    settled scene); the Embree scene is built once and kept in it.
    """
    import open3d as o3d

    grid = ray_grid(cam)
    h, w = cam.height, cam.width
    rot = np.asarray(rotation, dtype=np.float64)
    origin = np.asarray(position, dtype=np.float64)
    norm = grid.norm.ravel()
    dirs_w = (grid.dirs.reshape(-1, 3) @ rot.T.astype(np.float32)).astype(np.float32)
    z, ids, cos = _support(origin, dirs_w, norm, support)
    n_obj = len(meshes)
    meshes = list(meshes) + list(background)
    scene = None
    if meshes:
        scene = None if cache is None else cache.get("raycasting_scene")
        if scene is None:
            scene = o3d.t.geometry.RaycastingScene(nthreads=threads)
            for v, t in meshes:
                scene.add_triangles(
                    o3d.core.Tensor(np.ascontiguousarray(v, dtype=np.float32)),
                    o3d.core.Tensor(np.ascontiguousarray(t, dtype=np.uint32)),
                )
            if cache is not None:
                cache["raycasting_scene"] = scene
        cand = _candidates(meshes, cam, grid, rot, origin)
        if len(cand):
            t, gid, c = _cast(scene, origin.astype(np.float32), dirs_w[cand], norm[cand], threads)
            nearer = t < z[cand]
            sel = cand[nearer]
            z[sel] = t[nearer]
            ids[sel] = _mesh_ids(gid[nearer], n_obj)
            cos[sel] = c[nearer]
    hit = ids != NO_HIT
    height = np.where(hit, origin[2] + np.where(hit, z, 0.0) * dirs_w[:, 2], 0.0).astype(np.float32)
    above = height
    if support is not None and support.curvature != 0.0:  # the table top z = k (x^2 + y^2) under each hit
        zh = np.where(hit, z, 0.0)
        xy2 = (origin[0] + zh * dirs_w[:, 0]) ** 2 + (origin[1] + zh * dirs_w[:, 1]) ** 2
        above = np.where(hit, height - support.curvature * xy2, 0.0).astype(np.float32)
    z = np.where(hit, z, 0.0).astype(np.float32)
    r = z * norm

    z2, r2, ids2 = z.reshape(h, w), r.reshape(h, w), ids.reshape(h, w)
    s = grid.sub_dirs.shape[2]
    edge = np.zeros(0, dtype=np.int64)
    if supersample and (scene is not None or support is not None):
        edge_mask = np.zeros((h, w), dtype=bool)
        for a, b in (((slice(None), slice(1, None)), (slice(None), slice(None, -1))),
                     ((slice(1, None), slice(None)), (slice(None, -1), slice(None)))):
            diff = (ids2[a] != ids2[b]) | (np.abs(r2[a] - r2[b]) > edge_jump_m)
            edge_mask[a] |= diff
            edge_mask[b] |= diff
        edge = np.flatnonzero(edge_mask)
    if len(edge):
        sub = grid.sub_dirs.reshape(-1, s, 3)[edge].reshape(-1, 3)
        sub_norm = np.linalg.norm(sub, axis=1)
        sub_w = (sub @ rot.T.astype(np.float32)).astype(np.float32)
        sz, sids, scos = _support(origin, sub_w, sub_norm, support)
        if scene is not None:
            t, gid, c = _cast(scene, origin.astype(np.float32), sub_w, sub_norm, threads)
            nearer = t < sz
            sz = np.where(nearer, t, sz)
            sids = np.where(nearer, _mesh_ids(gid, n_obj), sids)
            scos = np.where(nearer, c, scos)
        sz = np.where(sids != NO_HIT, sz, 0.0)
        sub_r = (sz * sub_norm).reshape(-1, s)
        sub_ids, sub_cos = sids.reshape(-1, s), scos.reshape(-1, s)
    else:
        sub_r = np.zeros((0, s), np.float32)
        sub_ids = np.zeros((0, s), np.int32)
        sub_cos = np.zeros((0, s), np.float32)
    return RenderResult(
        z=z2,
        r=r2.astype(np.float32),
        ids=ids2,
        cos_inc=cos.reshape(h, w),
        height=height.reshape(h, w),
        edge=edge,
        sub_r=sub_r.astype(np.float32),
        sub_ids=sub_ids.astype(np.int32),
        sub_cos=sub_cos.astype(np.float32),
        above_support=above.reshape(h, w),
    )
