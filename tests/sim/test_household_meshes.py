"""tools/household_meshes.py: the held-out shapes are valid closed-form meshes the simulator loads."""

from __future__ import annotations

import numpy as np
import pytest
from toolmod import load_tool

from sim.shapes import MeshLibrary


@pytest.fixture(scope="module")
def hh():
    return load_tool("household_meshes.py")


def test_every_kind_is_written_and_loads_in_the_simulator(hh, tmp_path):
    files = hh.write_meshes(tmp_path, per_kind=2, seed=0)
    assert len(files) == 2 * len(hh.KINDS)
    skipped: list[str] = []
    lib = MeshLibrary.scan(tmp_path, on_skip=lambda p, why: skipped.append(f"{p.name}: {why}"))
    assert skipped == [] and len(lib) == len(files)
    assert not list(tmp_path.glob("*.tmp"))  # written by rename


def test_same_seed_same_files_other_seed_other_shapes(hh, tmp_path):
    a = [p.read_bytes() for p in hh.write_meshes(tmp_path / "a", 1, seed=3)]
    b = [p.read_bytes() for p in hh.write_meshes(tmp_path / "b", 1, seed=3)]
    c = [p.read_bytes() for p in hh.write_meshes(tmp_path / "c", 1, seed=4)]
    assert a == b and a != c


def test_bowl_and_plate_are_open_with_a_raised_floor(hh):
    """The point of these kinds: a cavity (points of the profile fold back inwards) and a floor
    at least 0.15 radii up, i.e. >= 3 mm at the smallest drawn object (4 cm)."""
    for make in (hh.bowl, hh.plate):
        v, t = make(np.random.default_rng(0))
        r = np.hypot(v[:, 0], v[:, 1])
        centre_top = v[r < 1e-9][:, 2].max()
        assert centre_top >= 0.15 * r.max()
        assert v[:, 2].max() > centre_top + 0.05  # a rim above the floor: open, not a slab
