"""Objects to drop: procedural meshes and a user's mesh library.

Why procedural shapes: the paper drew from 10,809 downloaded models, which we cannot ship, and
it had to discard flat categories by hand (section III.B). Generating shapes ourselves means
nothing has to be downloaded, and every dimension is under control: the paper's own proposal
V.a, a minimum thickness, is a sampling constraint here instead of a clean-up step.

Each `Shape` carries two geometries in its own body frame:
- a render mesh (the full surface, a few hundred triangles: open3d's BVH build cost grows with
  the triangle count, so procedural meshes stay small and library meshes are decimated);
- collision parts for MuJoCo: native primitives where they exist (box, sphere, cylinder,
  capsule are far cheaper to collide than meshes) and otherwise a small point set whose convex
  hull MuJoCo computes (PITFALLS.md: "keep hulls small, render the full mesh").

Library meshes (.obj .stl .off .ply, read with open3d) are rescaled so their largest bounding
box side equals the sampled largest dimension and stretched along any side thinner than the
minimum thickness. A file that fails to load is reported once through a callback and skipped;
library code never prints.
"""

from __future__ import annotations

import math
from collections import OrderedDict
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from functools import lru_cache
from pathlib import Path
from typing import Any

import numpy as np

from edge.errors import ConfigError, DataError

__all__ = [
    "PROCEDURAL_KINDS",
    "THIN_KINDS",
    "MESH_SUFFIXES",
    "Part",
    "Shape",
    "make_shape",
    "random_procedural",
    "make_thin_shape",
    "random_thin",
    "LONG_KINDS",
    "make_long_shape",
    "random_long",
    "box_mesh",
    "fit_mesh",
    "MeshLibrary",
]

# The built-in generator. "tube" (a hollow cylinder) stands in for the paper's toilet-paper rolls.
PROCEDURAL_KINDS = (
    "box",
    "cylinder",
    "sphere",
    "capsule",
    "cone",
    "torus",
    "tube",
    "superquadric",
    "hull",
    "union",
)
MESH_SUFFIXES = (".obj", ".stl", ".off", ".ply")
# Thin objects (scene.thin_fraction): flat things a floor-plane fit swallows. They ignore the
# minimum thickness on purpose; their thickness comes from scene.thin_thickness_m.
THIN_KINDS = ("disc", "plate", "ring", "bar", "lshape")
# Long objects (scene.long_fraction): handles, pens, rods and sticks 12-30 cm long and 1-4 cm
# across, beyond Table I's 10 cm. A real capture showed why: a brush handle lying across other
# objects, 1-3 cm above the table, was missed by a model that had never seen anything so long
# and narrow (it looks like a tray rim, which is background).
LONG_KINDS = ("rod", "handle", "stick")

# Render mesh resolution: enough for 1-2 px accuracy at 20 cm, small enough for a fast BVH.
_SEG = 24  # segments around an axis of revolution
_RINGS = 10  # rings along a profile arc / latitude bands
_HULL_VERTS = 24  # collision hull size for library meshes
_HULL_SEG = 12  # segments of coarse collision rings (cone, torus, superquadric)
_LIB_MAX_TRIS = 1500  # library meshes above this are decimated for ray casting


@dataclass(frozen=True, eq=False)
class Part:
    """One MuJoCo collision geom in the body frame.

    ``size`` follows MuJoCo: box half-sides; sphere (radius,); cylinder and capsule (radius,
    half-length along z); hull: unused, ``points`` holds the vertices whose hull collides.
    ``quat`` is (w, x, y, z).
    """

    kind: str
    size: tuple[float, ...] = ()
    pos: tuple[float, float, float] = (0.0, 0.0, 0.0)
    quat: tuple[float, float, float, float] = (1.0, 0.0, 0.0, 0.0)
    points: np.ndarray | None = None


@dataclass(eq=False)
class Shape:
    """A droppable object: render mesh + collision parts, both in the body frame (metres)."""

    kind: str
    vertices: np.ndarray  # float32 (N, 3)
    triangles: np.ndarray  # int32 (M, 3)
    parts: tuple[Part, ...]
    params: dict[str, Any] = field(default_factory=dict)

    @property
    def extents(self) -> np.ndarray:
        """Axis-aligned bounding-box sides in the body frame."""
        return self.vertices.max(0) - self.vertices.min(0)


# --------------------------------------------------------------------------- mesh helpers


def _quat_from_matrix(r: np.ndarray) -> tuple[float, float, float, float]:
    """(w, x, y, z) of a rotation matrix (Shepperd's method, numerically safe)."""
    m = np.asarray(r, dtype=float)
    tr = m[0, 0] + m[1, 1] + m[2, 2]
    if tr > 0:
        s = math.sqrt(tr + 1.0) * 2
        q = (0.25 * s, (m[2, 1] - m[1, 2]) / s, (m[0, 2] - m[2, 0]) / s, (m[1, 0] - m[0, 1]) / s)
    elif m[0, 0] > m[1, 1] and m[0, 0] > m[2, 2]:
        s = math.sqrt(1.0 + m[0, 0] - m[1, 1] - m[2, 2]) * 2
        q = ((m[2, 1] - m[1, 2]) / s, 0.25 * s, (m[0, 1] + m[1, 0]) / s, (m[0, 2] + m[2, 0]) / s)
    elif m[1, 1] > m[2, 2]:
        s = math.sqrt(1.0 + m[1, 1] - m[0, 0] - m[2, 2]) * 2
        q = ((m[0, 2] - m[2, 0]) / s, (m[0, 1] + m[1, 0]) / s, 0.25 * s, (m[1, 2] + m[2, 1]) / s)
    else:
        s = math.sqrt(1.0 + m[2, 2] - m[0, 0] - m[1, 1]) * 2
        q = ((m[1, 0] - m[0, 1]) / s, (m[0, 2] + m[2, 0]) / s, (m[1, 2] + m[2, 1]) / s, 0.25 * s)
    n = math.sqrt(sum(c * c for c in q))
    return tuple(float(c / n) for c in q)  # type: ignore[return-value]


def _random_rotation(rng: np.random.Generator) -> np.ndarray:
    q = rng.normal(size=4)
    q /= np.linalg.norm(q)
    w, x, y, z = q
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


@lru_cache(maxsize=256)
def _grid_triangles(rows: int, cols: int, wrap_rows: bool, pole_first: bool = False, pole_last: bool = False) -> np.ndarray:
    """Two triangles per quad of a rows x cols vertex grid that wraps around the columns.

    A pole row (all its vertices at one point) keeps only the triangle of each quad that is
    not degenerate. Cached: the topology depends only on the grid size.
    """
    j = np.arange(rows if wrap_rows else rows - 1)
    i = np.arange(cols)
    jj, ii = np.meshgrid(j, i, indexing="ij")
    j1 = (jj + 1) % rows
    i1 = (ii + 1) % cols
    a, b, c, d = jj * cols + ii, j1 * cols + ii, j1 * cols + i1, jj * cols + i1
    t1 = np.stack([a, b, c], -1)  # degenerate where row j1 is a pole
    t2 = np.stack([a, c, d], -1)  # degenerate where row j is a pole
    keep1 = np.ones(jj.shape, bool)
    keep2 = np.ones(jj.shape, bool)
    if pole_first:
        keep2 &= jj != 0
    if pole_last:
        keep1 &= j1 != rows - 1
    t = np.concatenate([t1[keep1], t2[keep2]]).astype(np.int32)
    t.flags.writeable = False
    return t


def _clean(vertices: np.ndarray, triangles: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Drop zero-area triangles (for meshes whose degenerate faces are not known up front)."""
    v = np.asarray(vertices, dtype=np.float64)
    t = np.asarray(triangles, dtype=np.int64)
    area2 = np.linalg.norm(np.cross(v[t[:, 1]] - v[t[:, 0]], v[t[:, 2]] - v[t[:, 0]]), axis=1)
    t = t[area2 > 1e-12 * max(float(np.ptp(v)), 1e-9) ** 2]
    return v.astype(np.float32), t.astype(np.int32)


def _revolve(profile: Sequence[tuple[float, float]], closed: bool = False, seg: int = _SEG):
    """Surface of revolution about z from an (r, z) polyline; open profiles end on the axis."""
    p = np.asarray(profile, dtype=float)
    p[np.abs(p[:, 0]) < 1e-12, 0] = 0.0  # arcs ending on the axis: exact poles
    th = np.linspace(0.0, 2 * np.pi, seg, endpoint=False)
    v = np.empty((len(p), seg, 3))
    v[..., 0] = p[:, None, 0] * np.cos(th)[None]
    v[..., 1] = p[:, None, 0] * np.sin(th)[None]
    v[..., 2] = p[:, None, 1]
    poles = (not closed and p[0, 0] == 0.0, not closed and p[-1, 0] == 0.0)
    return v.reshape(-1, 3).astype(np.float32), _grid_triangles(len(p), seg, closed, *poles)


def _arc(cr: float, cz: float, radius: float, a0: float, a1: float, n: int) -> list[tuple[float, float]]:
    a = np.linspace(a0, a1, n)
    return [(cr + radius * math.cos(t), cz + radius * math.sin(t)) for t in a]


def _box_mesh(half: Sequence[float]) -> tuple[np.ndarray, np.ndarray]:
    h = np.asarray(half, dtype=float)
    corners = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], dtype=float) * h
    tris = np.array(
        [[0, 1, 3], [0, 3, 2], [4, 6, 7], [4, 7, 5], [0, 4, 5], [0, 5, 1],
         [2, 3, 7], [2, 7, 6], [0, 2, 6], [0, 6, 4], [1, 5, 7], [1, 7, 3]]
    )
    return corners.astype(np.float32), tris.astype(np.int32)


def box_mesh(half: Sequence[float]) -> tuple[np.ndarray, np.ndarray]:
    """Closed box mesh with half sides ``half``, centred on the origin (tray walls use it)."""
    return _box_mesh(half)


def _spow(x: np.ndarray, e: float) -> np.ndarray:
    return np.sign(x) * np.abs(x) ** e


def _hull_points(vertices: np.ndarray, limit: int = _HULL_VERTS, rng: np.random.Generator | None = None) -> np.ndarray:
    """At most ``limit`` hull vertices: farthest-point sampling keeps the extremes of the shape."""
    from scipy.spatial import ConvexHull

    v = np.asarray(vertices, dtype=np.float64)
    try:
        v = v[ConvexHull(v).vertices]
    except Exception:  # degenerate (flat) input: keep the raw points, MuJoCo reports if unusable
        pass
    if len(v) <= limit:
        return v
    chosen = [int(np.argmax(np.linalg.norm(v - v.mean(0), axis=1)))]
    d = np.linalg.norm(v - v[chosen[0]], axis=1)
    for _ in range(limit - 1):
        k = int(np.argmax(d))
        chosen.append(k)
        d = np.minimum(d, np.linalg.norm(v - v[k], axis=1))
    return v[chosen]


def _ring_points(profile: Sequence[tuple[float, float]], seg: int | None = None) -> np.ndarray:
    """Collision points of a solid of revolution: a coarse ring per (r, z) profile point."""
    seg = seg or _HULL_SEG
    th = np.linspace(0.0, 2 * np.pi, seg, endpoint=False)
    # rings circumscribe the true circle so the coarse hull does not sink into the floor
    k = 1.0 / math.cos(math.pi / seg)
    return np.array([[r * k * math.cos(a), r * k * math.sin(a), z] for r, z in profile for a in th])


def _centre(vertices: np.ndarray) -> np.ndarray:
    return (vertices.max(0) + vertices.min(0)) / 2.0


# --------------------------------------------------------------------------- sizing


def _dims(rng: np.random.Generator, largest: float, thin: float, n: int) -> np.ndarray:
    """n sizes: the largest equals ``largest``, none below ``thin`` (paper V.a)."""
    lo = min(thin, largest)
    d = rng.uniform(lo, largest, size=n)
    d[rng.integers(n)] = largest
    return d


def fit_mesh(vertices: np.ndarray, largest: float, thin: float) -> tuple[np.ndarray, np.ndarray]:
    """Scale so the largest bounding-box side is ``largest``; stretch sides under ``thin``.

    Returns the fitted vertices (centred on the box centre) and the per-axis scale applied.
    Stretching is the paper's V.a proposal: an object so flat that it vanishes into the floor
    would teach the network to label floor as object.
    """
    v = np.asarray(vertices, dtype=np.float64)
    v = v - _centre(v)
    ext = v.max(0) - v.min(0)
    if not np.all(np.isfinite(ext)) or ext.max() <= 0:
        raise DataError("mesh has no extent (all vertices coincide)")
    s = largest / ext.max()
    scale = np.full(3, s)
    ext_s = ext * s
    small = ext_s < thin
    if np.any(ext[small] <= ext.max() * 1e-9):
        raise DataError("mesh is flat (zero thickness along one axis); it cannot be given a minimum thickness")
    scale[small] = thin / ext[small]
    v = v * scale
    return v, scale


# --------------------------------------------------------------------------- procedural shapes


def _box_shape(d: np.ndarray):
    """A box of side lengths ``d`` with its native collider: (verts, tris, parts, params)."""
    v, t = _box_mesh(d / 2)
    return v, t, (Part("box", tuple(d / 2)),), {"size_m": d.round(5).tolist()}


def _box(rng, largest, thin):
    return _box_shape(_dims(rng, largest, thin, 3))


def _cylinder_mesh(r: float, h: float):
    """Closed cylinder of radius r and half height h along body z, with its native collider."""
    v, t = _revolve([(0, -h), (r, -h), (r, h), (0, h)])
    return v, t, (Part("cylinder", (r, h)),)


def _capsule_mesh(r: float, h: float):
    """Capsule of radius r whose straight part has half length h along body z."""
    prof = _arc(0, -h, r, -np.pi / 2, 0, _RINGS // 2 + 1) + _arc(0, h, r, 0, np.pi / 2, _RINGS // 2 + 1)
    v, t = _revolve(prof)
    return v, t, (Part("capsule", (r, h)),)


def _cylinder(rng, largest, thin):
    diam, height = _dims(rng, largest, thin, 2)
    v, t, parts = _cylinder_mesh(diam / 2, height / 2)
    return v, t, parts, {"diameter_m": round(diam, 5), "height_m": round(height, 5)}


def _sphere(rng, largest, thin):
    r = largest / 2
    v, t = _revolve(_arc(0, 0, r, -np.pi / 2, np.pi / 2, _RINGS + 1), seg=_SEG)
    return v, t, (Part("sphere", (r,)),), {"diameter_m": round(largest, 5)}


def _capsule(rng, largest, thin):
    diam = rng.uniform(min(thin, largest), largest * 0.8)
    v, t, parts = _capsule_mesh(diam / 2, max(largest / 2 - diam / 2, 1e-4))
    return v, t, parts, {"diameter_m": round(diam, 5), "length_m": round(largest, 5)}


def _cone(rng, largest, thin):
    diam, height = _dims(rng, largest, thin, 2)
    r, h = diam / 2, height / 2
    top = r * rng.uniform(0.0, 0.6)  # 0: a sharp cone, else a frustum
    v, t = _revolve([(0, -h), (r, -h), (top, h), (0, h)])
    pts = _ring_points([(r, -h), (top, h)] if top > 0 else [(r, -h)])
    if top == 0:
        pts = np.vstack([pts, [[0.0, 0.0, h]]])
    return v, t, (Part("hull", points=pts),), {
        "diameter_m": round(diam, 5),
        "height_m": round(height, 5),
        "top_ratio": round(top / r, 4),
    }


def _torus(rng, largest, thin):
    outer = largest / 2
    tube = rng.uniform(max(thin / 2, 0.15 * outer), 0.45 * outer)
    rc = outer - tube
    v, t = _revolve(_arc(rc, 0, tube, 0, 2 * np.pi, _RINGS + 2)[:-1], closed=True)
    # The hull only needs the outer half of the tube profile.
    pts = _ring_points(_arc(rc, 0, tube, -np.pi / 2, np.pi / 2, 5))
    return v, t, (Part("hull", points=pts),), {"outer_diameter_m": round(largest, 5), "tube_radius_m": round(tube, 5)}


def _tube(rng, largest, thin):
    diam, height = _dims(rng, largest, thin, 2)
    ro, h = diam / 2, height / 2
    ri = ro * rng.uniform(0.3, 0.85)
    v, t = _revolve([(ri, -h), (ro, -h), (ro, h), (ri, h)], closed=True)
    # Collides as its outer cylinder: nothing falls into the hole, which is rarely visible anyway.
    return v, t, (Part("cylinder", (ro, h)),), {"diameter_m": round(diam, 5), "height_m": round(height, 5), "inner_ratio": round(ri / ro, 4)}


def _superquadric(rng, largest, thin):
    a = _dims(rng, largest, thin, 3) / 2
    # Exponents <= 1.6 keep the surface convex, so its hull is a faithful collision shape.
    e1, e2 = rng.uniform(0.25, 1.6, size=2)
    eta = np.linspace(-np.pi / 2, np.pi / 2, _RINGS + 3)
    om = np.linspace(-np.pi, np.pi, _SEG, endpoint=False)
    ee, oo = np.meshgrid(eta, om, indexing="ij")
    ce, se, co, so = np.cos(ee), np.sin(ee), np.cos(oo), np.sin(oo)
    v = np.stack(
        [a[0] * _spow(ce, e1) * _spow(co, e2), a[1] * _spow(ce, e1) * _spow(so, e2), a[2] * _spow(se, e1)], -1
    ).reshape(-1, 3)
    v, t = v.astype(np.float32), _grid_triangles(len(eta), len(om), False, True, True)
    # Collision: the same surface on a coarse grid (poles once); MuJoCo takes its hull.
    ce, om2 = np.linspace(-np.pi / 2, np.pi / 2, 7)[1:-1], np.linspace(-np.pi, np.pi, _HULL_SEG, endpoint=False)
    e2g, o2g = np.meshgrid(ce, om2, indexing="ij")
    c1, s1, c2, s2 = np.cos(e2g), np.sin(e2g), np.cos(o2g), np.sin(o2g)
    pts = np.stack([a[0] * _spow(c1, e1) * _spow(c2, e2), a[1] * _spow(c1, e1) * _spow(s2, e2), a[2] * _spow(s1, e1)], -1)
    pts = np.vstack([pts.reshape(-1, 3), [[0, 0, -a[2]], [0, 0, a[2]]]])
    return v, t, (Part("hull", points=pts),), {
        "semi_axes_m": a.round(5).tolist(),
        "exponents": [round(float(e1), 4), round(float(e2), 4)],
    }


def _hull(rng, largest, thin):
    from scipy.spatial import ConvexHull

    n = int(rng.integers(8, 25))
    p = rng.normal(size=(n, 3))
    p /= np.linalg.norm(p, axis=1, keepdims=True)
    p *= rng.uniform(0.5, 1.0, size=(n, 1))
    p *= _dims(rng, 1.0, 0.2, 3)  # anisotropic before fitting
    p, _ = fit_mesh(p, largest, thin)
    hull = ConvexHull(p)
    remap = np.full(len(p), -1)
    remap[hull.vertices] = np.arange(len(hull.vertices))
    v, t = _clean(p[hull.vertices], remap[hull.simplices])
    return v, t, (Part("hull", points=v.astype(np.float64)),), {"points": int(len(v))}


def _union(rng, largest, thin):
    """2-4 primitives glued together (toys, tools): each part thick enough on its own."""
    n = int(rng.integers(2, 5))
    parts: list[Part] = []
    verts: list[np.ndarray] = []
    tris: list[np.ndarray] = []
    kinds: list[str] = []
    base = largest * 0.6
    offset = 0
    for k in range(n):
        kind = str(rng.choice(["box", "cylinder", "sphere", "capsule"]))
        gen = {"box": _box, "cylinder": _cylinder, "sphere": _sphere, "capsule": _capsule}[kind]
        v, t, (p,), _ = gen(rng, rng.uniform(0.55, 1.0) * base, thin)
        r = np.eye(3) if k == 0 else _random_rotation(rng)
        c = np.zeros(3) if k == 0 else (rng.uniform(-0.5, 0.5, 3) * (np.concatenate(verts).max(0) - np.concatenate(verts).min(0)))
        verts.append(v.astype(np.float64) @ r.T + c)
        tris.append(t + offset)
        offset += len(v)
        parts.append(Part(p.kind, p.size, tuple(c), _quat_from_matrix(r), p.points))
        kinds.append(kind)
    v = np.concatenate(verts)
    ext = v.max(0) - v.min(0)
    centre = _centre(v)
    s = largest / ext.max()  # uniform: primitives stay primitives
    v = (v - centre) * s
    parts = [
        Part(
            p.kind,
            tuple(x * s for x in p.size),
            tuple((np.asarray(p.pos) - centre) * s),
            p.quat,
            None if p.points is None else (p.points - centre) * s,
        )
        for p in parts
    ]
    return v.astype(np.float32), np.concatenate(tris).astype(np.int32), tuple(parts), {"parts": kinds}


_GENERATORS: dict[str, Callable] = {
    "box": _box,
    "cylinder": _cylinder,
    "sphere": _sphere,
    "capsule": _capsule,
    "cone": _cone,
    "torus": _torus,
    "tube": _tube,
    "superquadric": _superquadric,
    "hull": _hull,
    "union": _union,
}


def _generate(generators: dict[str, Callable], what: str, kind: str, rng: np.random.Generator, largest: float,
              side: float, params: dict[str, Any]) -> Shape:
    """The one dispatch of both families: ``generators[kind](rng, largest, side)`` as a `Shape`
    whose params are ``params`` followed by the generator's own."""
    if kind not in generators:
        raise ConfigError(f"unknown {what} '{kind}'; choose from {list(generators)}")
    v, t, parts, own = generators[kind](rng, float(largest), float(side))
    return Shape(kind, np.asarray(v, np.float32), np.asarray(t, np.int32), tuple(parts), {**params, **own})


def make_shape(kind: str, rng: np.random.Generator, largest: float, thin: float) -> Shape:
    """One procedural shape of ``kind`` with largest side ``largest`` and no side under ``thin``."""
    return _generate(_GENERATORS, "shape", kind, rng, largest, thin, {"largest_m": round(float(largest), 5)})


def random_procedural(
    rng: np.random.Generator, largest: float, thin: float, kinds: Sequence[str], weights: Sequence[float] | None = None
) -> Shape:
    p = None if weights is None else np.asarray(weights, float) / float(np.sum(weights))
    return make_shape(str(kinds[int(rng.choice(len(kinds), p=p))]), rng, largest, thin)


# --------------------------------------------------------------------------- thin shapes


def _zquat(a: float) -> tuple[float, float, float, float]:
    return (math.cos(a / 2), 0.0, 0.0, math.sin(a / 2))


def _disc(rng, largest, thick):
    """A coin / lid: collides as a native cylinder, flat faces along body z."""
    r, h = largest / 2, thick / 2
    v, t = _revolve([(0, -h), (r, -h), (r, h), (0, h)])
    return v, t, (Part("cylinder", (r, h)),), {"diameter_m": round(largest, 5)}


def _plate(rng, largest, thick):
    """A card / lid / cutting board: a thin box."""
    d = np.array([largest, rng.uniform(0.4, 1.0) * largest, thick])
    return _box_shape(d)


def _ring_shape(rng, largest, thick, seg: int = 8):
    """A washer / flat ring: collides as ``seg`` boxes so other objects can fall into the hole."""
    ro, h = largest / 2, thick / 2
    ri = ro * rng.uniform(0.45, 0.85)
    v, t = _revolve([(ri, -h), (ro, -h), (ro, h), (ri, h)], closed=True)
    rm, half_w = (ro + ri) / 2, (ro - ri) / 2
    half_l = rm * math.tan(math.pi / seg) + half_w * 0.5  # segments overlap at the joints
    parts = tuple(
        Part("box", (half_w, half_l, h), (rm * math.cos(a), rm * math.sin(a), 0.0), _zquat(a))
        for a in np.linspace(0.0, 2 * np.pi, seg, endpoint=False)
    )
    return v, t, parts, {"outer_diameter_m": round(largest, 5), "inner_ratio": round(ri / ro, 4)}


def _bar(rng, largest, thick):
    """A ruler / spatula / flat tool: long and narrow."""
    d = np.array([largest, max(rng.uniform(0.08, 0.25) * largest, thick), thick])
    return _box_shape(d)


def _lshape(rng, largest, thick):
    """An L-square / bracket: two flat bars at a right angle, centred on their bounding box."""
    a, b = largest, rng.uniform(0.4, 0.9) * largest
    w = max(rng.uniform(0.12, 0.3) * largest, thick)
    boxes = [(np.array([a / 2, w / 2, 0.0]), np.array([a, w, thick]) / 2),
             (np.array([w / 2, b / 2, 0.0]), np.array([w, b, thick]) / 2)]
    centre = np.array([a / 2, b / 2, 0.0])
    verts, tris, parts = [], [], []
    for k, (c, half) in enumerate(boxes):
        bv, bt = _box_mesh(half)
        verts.append(bv.astype(np.float64) + c - centre)
        tris.append(bt + 8 * k)
        parts.append(Part("box", tuple(half), tuple(c - centre)))
    v = np.concatenate(verts).astype(np.float32)
    return v, np.concatenate(tris).astype(np.int32), tuple(parts), {"arms_m": [round(a, 5), round(float(b), 5)], "width_m": round(float(w), 5)}


_THIN_GENERATORS: dict[str, Callable] = {
    "disc": _disc,
    "plate": _plate,
    "ring": _ring_shape,
    "bar": _bar,
    "lshape": _lshape,
}


def make_thin_shape(kind: str, rng: np.random.Generator, largest: float, thickness: float) -> Shape:
    """A flat shape of ``kind``: largest side ``largest``, flat along body z with ``thickness``."""
    info = {"largest_m": round(float(largest), 5), "thickness_m": round(float(thickness), 5), "thin": True}
    return _generate(_THIN_GENERATORS, "thin shape", kind, rng, largest, thickness, info)


def _pick(rng: np.random.Generator, kinds: Sequence[str]) -> str:
    """One of ``kinds``, uniformly (one integer draw)."""
    return str(kinds[int(rng.integers(len(kinds)))])


def random_thin(rng: np.random.Generator, largest: float, thickness: float, kinds: Sequence[str]) -> Shape:
    return make_thin_shape(_pick(rng, kinds), rng, largest, thickness)


# --------------------------------------------------------------------------- long shapes


def _rod(rng, length, diam):
    """A pen / pipe / round handle: a cylinder along body z."""
    return (*_cylinder_mesh(diam / 2, length / 2), {})


def _handle(rng, length, diam):
    """A rounded handle / tube of paste: a capsule along body z."""
    return (*_capsule_mesh(diam / 2, max(length / 2 - diam / 2, 1e-4)), {})


def _stick(rng, length, diam):
    """A wooden spoon's handle / a square rod: a box along body z, its cross-section not square."""
    d = np.array([diam, diam * rng.uniform(0.5, 1.5), length])
    return _box_shape(d)


_LONG_GENERATORS: dict[str, Callable] = {"rod": _rod, "handle": _handle, "stick": _stick}


def make_long_shape(kind: str, rng: np.random.Generator, length: float, diameter: float) -> Shape:
    """A long narrow shape of ``kind``: ``length`` along body z, about ``diameter`` across."""
    info = {"length_m": round(float(length), 5), "diameter_m": round(float(diameter), 5), "long": True}
    return _generate(_LONG_GENERATORS, "long shape", kind, rng, length, diameter, info)


def random_long(rng: np.random.Generator, length: float, diameter: float, kinds: Sequence[str]) -> Shape:
    return make_long_shape(_pick(rng, kinds), rng, length, diameter)


# --------------------------------------------------------------------------- mesh library


@dataclass(frozen=True, eq=False)
class _Loaded:
    vertices: np.ndarray  # float64, centred, original units
    triangles: np.ndarray  # int32


MAX_MESH_BYTES = 64 << 20  # a library object is decimated to 1,500 triangles; a bigger file is not worth the memory
_PLY_SIZES = {"char": 1, "uchar": 1, "int8": 1, "uint8": 1, "short": 2, "ushort": 2, "int16": 2, "uint16": 2,
              "int": 4, "uint": 4, "int32": 4, "uint32": 4, "float": 4, "float32": 4, "double": 8, "float64": 8}


def _declared_fits(path: Path) -> None:
    """Refuse a mesh whose header declares more vertices or faces than the file can hold.

    Why: open3d sizes its arrays from the header; a 30-byte OFF declaring 200 million vertices
    takes 3.8 GB and minutes before it fails. An element needs at least a few bytes of file
    (ASCII: a digit and a separator per value; binary: its declared sizes).
    """
    size = path.stat().st_size
    if size > MAX_MESH_BYTES:
        raise DataError(f"{path.name}: {size} bytes is above the mesh size limit of {MAX_MESH_BYTES}; decimate it first")
    suffix = path.suffix.lower()
    with open(path, "rb") as fh:
        head = fh.read(65536)
    need = 0
    if suffix == ".ply" and head.startswith(b"ply"):
        end = head.find(b"end_header")
        lines = head[: end if end >= 0 else len(head)].decode("ascii", "replace").splitlines()
        binary = any(ln.split()[:2] and ln.split()[0] == "format" and "binary" in ln for ln in lines)
        rows: list[list[int]] = []  # [count, min bytes per row]
        for ln in lines:
            parts = ln.split()
            if parts[:1] == ["element"] and len(parts) == 3 and parts[2].isdigit():
                rows.append([int(parts[2]), 0])
            elif parts[:1] == ["property"] and rows:
                if binary:
                    kind = parts[2] if len(parts) > 2 and parts[1] == "list" else (parts[1] if len(parts) > 1 else "")
                    rows[-1][1] += _PLY_SIZES.get(kind, 1)
                else:
                    rows[-1][1] += 2
        need = sum(count * max(per, 1) for count, per in rows)
    elif suffix == ".off":
        tokens = [t for ln in head.decode("ascii", "replace").splitlines() if not ln.lstrip().startswith("#")
                  for t in ln.split()]
        nums = [t for t in tokens[:8] if t.isdigit()]
        if len(nums) >= 2:
            need = int(nums[0]) * 6 + int(nums[1]) * 8  # "0 0 0\n" per vertex, "3 0 1 2\n" per face
    elif suffix == ".stl" and not head.lstrip().startswith(b"solid") and len(head) >= 84:
        need = 84 + 50 * int.from_bytes(head[80:84], "little")
    if need > size:
        raise DataError(f"{path.name}: header declares more vertices or faces than its {size} bytes can hold (damaged file)")


def _read_mesh(path: Path) -> _Loaded:
    """Read and sanity-check one mesh file; raise DataError with the reason when unusable."""
    if path.suffix.lower() not in MESH_SUFFIXES:
        raise DataError(f"{path.name}: unsupported mesh format; use one of {list(MESH_SUFFIXES)}")
    _declared_fits(path)
    import open3d as o3d

    o3d.utility.set_verbosity_level(o3d.utility.VerbosityLevel.Error)
    try:
        mesh = o3d.io.read_triangle_mesh(str(path))
    except Exception as exc:  # open3d raises RuntimeError on some malformed files
        raise DataError(f"{path.name}: cannot read mesh ({exc})") from None
    v = np.asarray(mesh.vertices, dtype=np.float64)
    t = np.asarray(mesh.triangles, dtype=np.int64)
    if len(v) < 4 or len(t) < 1:
        raise DataError(f"{path.name}: no triangles could be read (corrupt or empty mesh)")
    if not np.all(np.isfinite(v)) or t.min() < 0 or t.max() >= len(v):
        raise DataError(f"{path.name}: mesh has non-finite vertices or bad face indices")
    ext = v.max(0) - v.min(0)
    if ext.max() <= 0:
        raise DataError(f"{path.name}: mesh has no extent (all vertices coincide)")
    if ext.min() <= ext.max() * 1e-9:
        raise DataError(f"{path.name}: mesh is flat (zero thickness); it cannot be given a minimum thickness")
    if len(t) > _LIB_MAX_TRIS:
        mesh = mesh.simplify_quadric_decimation(target_number_of_triangles=_LIB_MAX_TRIS)
        v2 = np.asarray(mesh.vertices, dtype=np.float64)
        t2 = np.asarray(mesh.triangles, dtype=np.int64)
        if len(t2) >= 4 and np.all(np.isfinite(v2)):
            v, t = v2, t2
    v = v - _centre(v)
    return _Loaded(v, t.astype(np.int32))


class MeshLibrary:
    """The user's ``--objects DIR``: every readable mesh file, loaded lazily and cached.

    `scan` checks each file once up front so that a frame's object draw only chooses among
    usable meshes (otherwise a frame would depend on which files failed in which worker).
    Problems go to ``on_skip(path, reason)``: the CLI prints them, tests collect them.
    """

    def __init__(self, paths: Sequence[Path], cache_size: int = 256) -> None:
        self.paths = [Path(p) for p in paths]
        self._cache: OrderedDict[int, _Loaded] = OrderedDict()
        self._cache_size = cache_size

    @staticmethod
    def list_files(folder: str | Path) -> list[Path]:
        d = Path(folder)
        if not d.exists():
            raise ConfigError(f"`objects` {d}: no such folder; give a folder of .obj/.stl/.off/.ply meshes")
        if not d.is_dir():
            raise ConfigError(f"`objects` {d}: not a folder; give a folder of .obj/.stl/.off/.ply meshes")
        files = sorted(p for p in d.rglob("*") if p.is_file() and p.suffix.lower() in MESH_SUFFIXES)
        if not files:
            raise ConfigError(f"`objects` {d}: no .obj/.stl/.off/.ply files in the folder")
        return files

    @classmethod
    def scan(
        cls,
        folder: str | Path,
        on_skip: Callable[[Path, str], None] | None = None,
        progress: Callable[[int], None] | None = None,
    ) -> MeshLibrary:
        """Load every mesh once; keep the good ones, report each bad one once."""
        good: list[Path] = []
        files = cls.list_files(folder)
        for p in files:
            try:
                _read_mesh(p)
                good.append(p)
            except DataError as exc:
                if on_skip is not None:
                    on_skip(p, str(exc))
            if progress is not None:
                progress(1)
        if not good:
            raise ConfigError(f"`objects` {folder}: none of the {len(files)} mesh files could be read")
        return cls(good)

    def __len__(self) -> int:
        return len(self.paths)

    def _get(self, i: int) -> _Loaded:
        if i in self._cache:
            self._cache.move_to_end(i)
            return self._cache[i]
        m = _read_mesh(self.paths[i])
        self._cache[i] = m
        if len(self._cache) > self._cache_size:
            self._cache.popitem(last=False)
        return m

    def shape(self, i: int, largest: float, thin: float) -> Shape:
        """Mesh ``i`` fitted to the sampled size; collides as its convex hull (<= 24 vertices)."""
        m = self._get(i)
        v, scale = fit_mesh(m.vertices, largest, thin)
        return Shape(
            "mesh",
            v.astype(np.float32),
            m.triangles,
            (Part("hull", points=_hull_points(v)),),
            {"file": self.paths[i].name, "largest_m": round(float(largest), 5), "scale": scale.round(6).tolist()},
        )
