"""Procedural shapes honour their size contract; every mesh format loads; bad meshes are skipped."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from edge.errors import ConfigError, DataError
from sim.shapes import PROCEDURAL_KINDS, THIN_KINDS, MeshLibrary, fit_mesh, make_shape, make_thin_shape


@pytest.mark.parametrize("kind", PROCEDURAL_KINDS)
def test_procedural_shape_size_contract(kind):
    rng = np.random.default_rng(3)
    for largest in (0.04, 0.07, 0.10):
        s = make_shape(kind, rng, largest, 0.012)
        ext = s.extents
        assert ext.max() == pytest.approx(largest, rel=0.03)
        assert ext.min() >= 0.012 * 0.97, f"{kind}: thinnest side {ext.min():.4f} under the minimum"
        assert s.triangles.min() >= 0 and s.triangles.max() < len(s.vertices)
        assert len(s.triangles) <= 2000  # small meshes keep the ray-casting BVH cheap
        assert s.parts, "a shape needs something to collide with"
        for p in s.parts:
            if p.kind == "hull":
                assert 4 <= len(p.points) <= 64  # MuJoCo keeps at most physics.max_hull_vertices


def test_unknown_shape_is_a_config_error():
    with pytest.raises(ConfigError, match="unknown shape 'blob'"):
        make_shape("blob", np.random.default_rng(0), 0.05, 0.01)


def test_each_family_refuses_the_others_kinds_and_lists_its_own():
    """make_shape and make_thin_shape share one dispatch; each keeps its own kinds and message."""
    with pytest.raises(ConfigError, match=r"unknown shape 'disc'; choose from \['box', .*'union'\]$"):
        make_shape("disc", np.random.default_rng(0), 0.05, 0.01)
    with pytest.raises(ConfigError, match=r"unknown thin shape 'box'; choose from \['disc', .*'lshape'\]$") as err:
        make_thin_shape("box", np.random.default_rng(0), 0.05, 0.003)
    assert str(list(THIN_KINDS)) in str(err.value)
    s = make_thin_shape("disc", np.random.default_rng(0), 0.05, 0.003)
    assert list(s.params) == ["largest_m", "thickness_m", "thin", "diameter_m"]
    assert list(make_shape("box", np.random.default_rng(0), 0.05, 0.01).params)[0] == "largest_m"


def test_fit_mesh_rescales_and_stretches_flat_meshes():
    v = np.array([[x, y, z] for x in (0, 10) for y in (0, 4) for z in (0, 0.1)], dtype=float)
    fitted, scale = fit_mesh(v, 0.08, 0.01)
    ext = fitted.max(0) - fitted.min(0)
    np.testing.assert_allclose(ext, [0.08, 0.032, 0.01], rtol=1e-9)
    assert scale[2] > scale[0]  # the flat axis was stretched (paper V.a)
    with pytest.raises(DataError, match="flat"):
        fit_mesh(v * [1, 1, 0], 0.08, 0.01)


def _box_mesh():
    import open3d as o3d

    m = o3d.geometry.TriangleMesh.create_box(2.0, 1.0, 0.5)
    m.compute_triangle_normals()
    m.compute_vertex_normals()
    return m


@pytest.fixture
def mesh_folder(tmp_path: Path) -> Path:
    import open3d as o3d

    m = _box_mesh()
    for ext in ("obj", "stl", "off", "ply"):
        assert o3d.io.write_triangle_mesh(str(tmp_path / f"box.{ext}"), m)
    return tmp_path


def test_each_mesh_format_loads_and_rescales(mesh_folder):
    skipped = []
    lib = MeshLibrary.scan(mesh_folder, on_skip=lambda p, r: skipped.append(p))
    assert skipped == []
    assert sorted(p.suffix for p in lib.paths) == [".obj", ".off", ".ply", ".stl"]
    for i in range(len(lib)):
        s = lib.shape(i, 0.06, 0.01)
        # 2 x 1 x 0.5 box scaled to a 6 cm largest side: 6 x 3 x 1.5 cm
        np.testing.assert_allclose(np.sort(s.extents), [0.015, 0.03, 0.06], atol=1e-5)
        assert s.parts[0].kind == "hull" and len(s.parts[0].points) >= 4


def test_corrupt_meshes_are_reported_once_and_skipped(mesh_folder):
    (mesh_folder / "garbage.obj").write_text("this is not a mesh\nv 1 2\nf 9 9 9\n")
    (mesh_folder / "empty.ply").write_bytes(b"")
    (mesh_folder / "truncated.stl").write_bytes(b"solid x\n facet normal 0 0 1\n outer loop\n vertex 0 0")
    (mesh_folder / "notes.txt").write_text("ignored: not a mesh suffix")
    reports: list[tuple[str, str]] = []
    lib = MeshLibrary.scan(mesh_folder, on_skip=lambda p, r: reports.append((p.name, r)))
    assert sorted(n for n, _ in reports) == ["empty.ply", "garbage.obj", "truncated.stl"]
    for name, reason in reports:
        assert name in reason  # the message names the file
    assert len(lib) == 4  # the good ones remain usable


def test_library_folder_errors(tmp_path):
    with pytest.raises(ConfigError, match="no such folder"):
        MeshLibrary.scan(tmp_path / "missing")
    with pytest.raises(ConfigError, match="no .obj/.stl/.off/.ply files"):
        MeshLibrary.scan(tmp_path)
    (tmp_path / "bad.obj").write_text("nothing\n")
    with pytest.raises(ConfigError, match="none of the 1 mesh files could be read"):
        MeshLibrary.scan(tmp_path)
