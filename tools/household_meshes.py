#!/usr/bin/env python
"""Write household-like object meshes the simulator's procedural library never draws.

Why: issue 9 will also be checked on "scenes of unseen scanned household objects", and no scanned
mesh set can be downloaded here. The next best held-out test is objects of *shapes the model
never saw in training*: open and concave ones (bowls, plates, mugs, cups), bottles, fruit,
bent bananas, spoons, hammers, non-convex prisms (stars, L-blocks, crosses), lidded boxes.
`sim.shapes` draws closed primitives, superquadrics, hulls and unions of them; none of these
has an open cavity, a rim or a non-convex outline. The meshes go to
``depthseg-sim --objects DIR``, which rescales each to the drawn object size (Table I),
drops it with convex-hull collision and labels it object: `tools/results_table.py` row
"unseen household-like meshes".

    .venv/bin/python tools/household_meshes.py data/household_meshes [--per-kind 6] [--seed 0]

Every random choice flows from ``--seed``; the same seed writes the same files. Numpy only.
"""

from __future__ import annotations

import argparse
import math
import sys
from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np

Mesh = tuple[np.ndarray, np.ndarray]  # (vertices [N, 3] float64, triangles [M, 3] int64)
SEG = 40  # segments around a solid of revolution


def revolve(profile: Sequence[tuple[float, float]], seg: int = SEG) -> Mesh:
    """Closed surface of revolution about z of an (r, z) polyline that starts and ends on the axis.

    Profiles may fold back (a bowl's outer wall up, its inner wall down): that is what makes the
    cavity. Points with r == 0 become single pole vertices.
    """
    pts = [(float(r), float(z)) for r, z in profile]
    verts: list[np.ndarray] = []
    rings: list[list[int] | int] = []
    ang = np.linspace(0.0, 2 * math.pi, seg, endpoint=False)
    for r, z in pts:
        if r <= 1e-9:
            rings.append(len(verts))
            verts.append(np.array([0.0, 0.0, z]))
        else:
            start = len(verts)
            verts.extend(np.stack([r * np.cos(ang), r * np.sin(ang), np.full(seg, z)], axis=1))
            rings.append(list(range(start, start + seg)))
    tris: list[tuple[int, int, int]] = []
    for a, b in zip(rings[:-1], rings[1:]):
        if isinstance(a, int) and isinstance(b, int):
            continue
        for k in range(seg):
            k2 = (k + 1) % seg
            if isinstance(a, int):
                tris.append((a, b[k2], b[k]))
            elif isinstance(b, int):
                tris.append((a[k], a[k2], b))
            else:
                tris.append((a[k], a[k2], b[k2]))
                tris.append((a[k], b[k2], b[k]))
    return np.asarray(verts, dtype=np.float64), np.asarray(tris, dtype=np.int64)


def sweep(path: np.ndarray, radius: np.ndarray, seg: int = 20) -> Mesh:
    """Closed tube of varying ``radius`` along a 3-D polyline ``path`` [N, 3], capped at both ends."""
    n = len(path)
    tang = np.gradient(path, axis=0)
    tang /= np.linalg.norm(tang, axis=1, keepdims=True)
    ref = np.array([0.0, 0.0, 1.0]) if abs(tang[0][2]) < 0.9 else np.array([1.0, 0.0, 0.0])
    ang = np.linspace(0.0, 2 * math.pi, seg, endpoint=False)
    verts = []
    for i in range(n):
        u = np.cross(tang[i], ref)
        u /= np.linalg.norm(u)
        w = np.cross(tang[i], u)
        verts.extend(path[i] + radius[i] * (np.cos(a) * u + np.sin(a) * w) for a in ang)
    caps = len(verts)
    verts += [path[0], path[-1]]
    tris = []
    for i in range(n - 1):
        for k in range(seg):
            a, b = i * seg + k, i * seg + (k + 1) % seg
            tris += [(a, b, b + seg), (a, b + seg, a + seg)]
    for k in range(seg):
        tris.append((caps, (k + 1) % seg, k))
        last = (n - 1) * seg
        tris.append((caps + 1, last + k, last + (k + 1) % seg))
    return np.asarray(verts, dtype=np.float64), np.asarray(tris, dtype=np.int64)


def prism(outline: np.ndarray, height: float) -> Mesh:
    """Closed extrusion of a simple (possibly non-convex) polygon [N, 2] from z = 0 to ``height``.

    Caps are a fan from the polygon's centroid: exact for star-shaped outlines (all used here are).
    """
    n = len(outline)
    c = outline.mean(axis=0)
    bottom = np.column_stack([outline, np.zeros(n)])
    top = np.column_stack([outline, np.full(n, height)])
    verts = np.vstack([bottom, top, [[c[0], c[1], 0.0], [c[0], c[1], height]]])
    tris = []
    for k in range(n):
        k2 = (k + 1) % n
        tris += [(k, k2, n + k2), (k, n + k2, n + k)]
        tris += [(2 * n, k2, k), (2 * n + 1, n + k, n + k2)]
    return verts, np.asarray(tris, dtype=np.int64)


def box(half: Sequence[float], centre: Sequence[float] = (0.0, 0.0, 0.0)) -> Mesh:
    hx, hy, hz = half
    v = np.array([[x, y, z] for x in (-hx, hx) for y in (-hy, hy) for z in (-hz, hz)], dtype=np.float64)
    t = np.array([[0, 1, 3], [0, 3, 2], [4, 6, 7], [4, 7, 5], [0, 4, 5], [0, 5, 1],
                  [2, 3, 7], [2, 7, 6], [0, 2, 6], [0, 6, 4], [1, 5, 7], [1, 7, 3]], dtype=np.int64)
    return v + np.asarray(centre), t


def merge(*meshes: Mesh) -> Mesh:
    """Several closed meshes as one (they may overlap: the ray caster takes the first hit)."""
    vs, ts, off = [], [], 0
    for v, t in meshes:
        vs.append(v)
        ts.append(t + off)
        off += len(v)
    return np.vstack(vs), np.vstack(ts)


# ------------------------------------------------------------------------------ the kinds
def bowl(rng: np.random.Generator) -> Mesh:
    """Open bowl on a foot ring; its inner floor lies 0.15-0.25 radii up (>= 3 mm at the smallest
    drawn size, 4 cm: the issue's thinnest object), as real bowls' do."""
    depth, base, wall = rng.uniform(0.45, 0.7), rng.uniform(0.3, 0.5), rng.uniform(0.04, 0.08)
    floor = rng.uniform(0.15, 0.25)
    outer = [(base + (1 - base) * math.sin(a), floor + (depth - floor) * (1 - math.cos(a)))
             for a in np.linspace(0.15, math.pi / 2, 8)]
    foot = [(0.0, floor - wall), (base * 0.8, floor - wall), (base * 0.8, 0.0), (base, 0.0)]
    inner = [(r - wall, max(z, floor)) for r, z in reversed(outer)]
    return revolve(foot + outer + inner + [(0.0, floor)])


def plate(rng: np.random.Generator) -> Mesh:
    """Saucer on a foot ring: flat centre 0.15-0.25 radii up, a raised rim (>= 3 mm at 4 cm)."""
    centre, rim, lip, t = rng.uniform(0.15, 0.25), rng.uniform(0.3, 0.4), rng.uniform(0.55, 0.75), 0.05
    return revolve([(0.0, centre - t), (lip * 0.8, centre - t), (lip * 0.8, 0.0), (lip, 0.0), (1.0, rim),
                     (1.0 - t, rim), (lip - t, centre), (0.0, centre)])


def mug(rng: np.random.Generator) -> Mesh:
    r, h, wall = rng.uniform(0.3, 0.45), 1.0, rng.uniform(0.03, 0.06)
    cup = revolve([(0.0, 0.0), (r, 0.0), (r, h), (r - wall, h), (r - wall, 0.06), (0.0, 0.06)])
    if rng.random() < 0.25:  # a cup without handle
        return cup
    hr = rng.uniform(0.22, 0.32) * h
    a = np.linspace(-math.pi / 2, math.pi / 2, 14)
    path = np.column_stack([r - 0.02 + hr * np.cos(a), np.zeros_like(a), h / 2 + hr * np.sin(a)])
    return merge(cup, sweep(path, np.full(len(a), rng.uniform(0.035, 0.06)), seg=10))


def bottle(rng: np.random.Generator) -> Mesh:
    r, shoulder, neck = rng.uniform(0.16, 0.3), rng.uniform(0.5, 0.7), rng.uniform(0.05, 0.1)
    return revolve([(0.0, 0.0), (r, 0.0), (r, shoulder), (neck, shoulder + 0.18), (neck, 1.0),
                    (neck * 1.3, 1.0), (neck * 1.3, 1.04), (0.0, 1.04)])


def fruit(rng: np.random.Generator) -> Mesh:
    """Apple or pear: a revolved bulge with a dimple on top."""
    pear = rng.random() < 0.5
    zs = np.linspace(0.0, 1.0, 12)
    if pear:
        rs = 0.45 * np.sin(np.pi * zs) ** 0.8 * (1.0 - 0.45 * zs)
    else:
        rs = 0.5 * np.sin(np.pi * zs) ** 0.6
    prof = [(0.0, 0.04)] + [(float(r), float(z)) for r, z in zip(rs[1:-1], zs[1:-1])] + [(0.0, 0.9)]
    return revolve(prof)


def banana(rng: np.random.Generator) -> Mesh:
    bend, n = rng.uniform(0.6, 1.2), 18
    a = np.linspace(-bend / 2, bend / 2, n)
    path = np.column_stack([np.sin(a), np.zeros(n), 1 - np.cos(a)])
    rad = rng.uniform(0.09, 0.13) * np.sin(np.linspace(0.15, np.pi - 0.15, n)) ** 0.5
    return sweep(path, rad, seg=12)


def spoon(rng: np.random.Generator) -> Mesh:
    """A shallow bowl (scoop) on a flat handle: thin, non-convex outline."""
    scoop_v, scoop_t = revolve([(0.0, 0.0), (0.25, 0.02), (0.3, 0.08), (0.27, 0.08), (0.22, 0.04), (0.0, 0.03)])
    scoop_v = scoop_v * np.array([1.0, rng.uniform(0.6, 0.8), 1.0])
    handle = box((0.4, rng.uniform(0.03, 0.06), 0.015), (0.65, 0.0, 0.06))
    return merge((scoop_v, scoop_t), handle)


def hammer(rng: np.random.Generator) -> Mesh:
    shaft = rng.uniform(0.035, 0.06)
    head = (rng.uniform(0.08, 0.12), rng.uniform(0.25, 0.35), rng.uniform(0.08, 0.12))
    a = np.linspace(0, 1, 2)
    handle = sweep(np.column_stack([a, np.zeros(2), np.zeros(2)]), np.full(2, shaft), seg=12)
    return merge(handle, box(head, (1.0, 0.0, 0.0)))


def star_prism(rng: np.random.Generator) -> Mesh:
    k = int(rng.integers(4, 7))
    a = np.linspace(0, 2 * math.pi, 2 * k, endpoint=False)
    r = np.where(np.arange(2 * k) % 2 == 0, 1.0, rng.uniform(0.4, 0.6))
    return prism(np.column_stack([r * np.cos(a), r * np.sin(a)]), rng.uniform(0.2, 0.6))


def l_block(rng: np.random.Generator) -> Mesh:
    """An L, T or cross outline (toy blocks, brackets): non-convex, star-shaped about its centroid."""
    w = rng.uniform(0.25, 0.4)
    kind = int(rng.integers(0, 3))
    if kind == 0:  # L: centroid inside for these proportions
        pts = [(0, 0), (1, 0), (1, w), (w, w), (w, 1), (0, 1)]
        outline = np.array(pts, dtype=np.float64)
        # fan from the corner square's centre, which sees every edge of the L
        outline = outline - np.array([w / 2, w / 2])
    elif kind == 1:  # T
        outline = np.array([(-0.5, 0), (0.5, 0), (0.5, w), (w / 2, w), (w / 2, 1), (-w / 2, 1), (-w / 2, w), (-0.5, w)])
        outline = outline - np.array([0.0, w / 2])
    else:  # cross
        h = w / 2
        outline = np.array([(h, -h), (h, -0.5), (-h, -0.5), (-h, -h), (-0.5, -h), (-0.5, h), (-h, h), (-h, 0.5),
                            (h, 0.5), (h, h), (0.5, h), (0.5, -h)])[::-1]
    v, t = prism(outline, rng.uniform(0.15, 0.4))
    if kind != 2:  # fan from the origin, which those outlines were shifted to
        v[-2, :2] = 0.0
        v[-1, :2] = 0.0
    return v, t


def lidded_box(rng: np.random.Generator) -> Mesh:
    hx, hy, hz = rng.uniform(0.5, 1.0), rng.uniform(0.4, 0.8), rng.uniform(0.2, 0.4)
    lip = rng.uniform(0.03, 0.06)
    return merge(box((hx, hy, hz)), box((hx + lip, hy + lip, 0.06), (0.0, 0.0, hz)))


KINDS: dict[str, Callable[[np.random.Generator], Mesh]] = {
    "bowl": bowl, "plate": plate, "mug": mug, "bottle": bottle, "fruit": fruit, "banana": banana,
    "spoon": spoon, "hammer": hammer, "star": star_prism, "lblock": l_block, "lidded_box": lidded_box,
}


def write_obj(path: Path, mesh: Mesh) -> None:
    """Wavefront OBJ, written to a temp file first and renamed (a half-written mesh never appears)."""
    v, t = mesh
    lines = [f"v {x:.6f} {y:.6f} {z:.6f}" for x, y, z in v] + [f"f {a + 1} {b + 1} {c + 1}" for a, b, c in t]
    tmp = path.with_suffix(path.suffix + ".tmp")
    tmp.write_text("\n".join(lines) + "\n")
    tmp.replace(path)


def write_meshes(out: Path, per_kind: int, seed: int) -> list[Path]:
    """``per_kind`` variants of every kind in ``out``; returns the files written."""
    out.mkdir(parents=True, exist_ok=True)
    files = []
    for i, (name, make) in enumerate(KINDS.items()):
        for j in range(per_kind):
            rng = np.random.default_rng([seed, i, j])
            v, t = make(rng)
            if not (np.all(np.isfinite(v)) and t.min() >= 0 and t.max() < len(v)):
                raise RuntimeError(f"{name} {j}: bad mesh")  # a bug in this file, not bad input
            p = out / f"{name}_{j:02d}.obj"
            write_obj(p, (v, t))
            files.append(p)
    return files


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("out", type=Path, help="folder to write the .obj files into")
    ap.add_argument("--per-kind", type=int, default=6, help="random variants of each kind (default %(default)s)")
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args(argv)
    if args.per_kind < 1:
        print("household_meshes: --per-kind must be >= 1", file=sys.stderr)
        return 2
    files = write_meshes(args.out, args.per_kind, args.seed)
    print(f"household_meshes: {len(files)} meshes of {len(KINDS)} kinds in {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
