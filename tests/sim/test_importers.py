"""Import of BlenSor scans and royaleviewer PLY captures into the depthseg MCAP layout."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from edge.errors import DataError
from edge.io import TOPIC_INFO, iter_frames
from sim import importers as imp

SHARED = Path(__file__).resolve().parents[2].parent / "shared"  # ../shared from the repo root
BLENSOR = SHARED / "data" / "blensor"
ROYALE = SHARED / "data" / "royale" / "royale_20200513_203219_0.ply"
W, H = 224, 171


def _need(path: Path) -> None:
    if not path.exists():
        pytest.skip(f"{path} is absent (shared data lives at ../shared next to the repo)")


def _plane_rms(depth: np.ndarray, intrinsics, mask: np.ndarray) -> float:
    """RMS distance (m) of the back-projected masked pixels from their best plane."""
    fx, fy, cx, cy = intrinsics
    v, u = np.nonzero(mask)
    z = depth[mask].astype(np.float64)
    p = np.stack([(u - cx) / fx * z, (v - cy) / fy * z, z], axis=1)
    p -= p.mean(axis=0)
    normal = np.linalg.svd(p, full_matrices=False)[2][2]
    return float(np.sqrt(((p @ normal) ** 2).mean()))


# ------------------------------------------------------------------------- synthetic (always run)


def _write_ply(path: Path, xyz: np.ndarray, grey: np.ndarray, header_extra: str = "", fmt: str = "ascii") -> None:
    n = xyz.shape[0]
    head = (
        f"ply\nformat {fmt} 1.0\ncomment test{header_extra}\nelement vertex {n}\n"
        "property float x\nproperty float y\nproperty float z\n"
        "property uchar red\nproperty uchar green\nproperty uchar blue\n"
        "element face 0\nproperty list uchar int vertex_index\nend_header\n"
    )
    rows = [f"{a:.6f} {b:.6f} {c:.6f} {g} {g} {g}" for (a, b, c), g in zip(xyz, grey)]
    path.write_text(head + "\n".join(rows) + "\n")


def _synthetic_capture(w: int = 16, h: int = 12, k=(20.0, 22.0, 7.6, 5.4), z0: float = 0.3):
    fx, fy, cx, cy = k
    v, u = np.mgrid[0:h, 0:w].astype(np.float64)
    z = z0 + 0.01 * u / w  # a slightly tilted plane
    xyz = np.stack([(u - cx) / fx * z, (v - cy) / fy * z, z], axis=-1)
    xyz[0, 0] = xyz[-1, -1] = 0.0  # two dead pixels
    grey = (np.arange(w * h) % 256).astype(np.uint8)
    return xyz.reshape(-1, 3), grey


def test_synthetic_ply_roundtrip(tmp_path):
    k = (20.0, 22.0, 7.6, 5.4)
    xyz, grey = _synthetic_capture(k=k)
    ply = tmp_path / "cap.ply"
    _write_ply(ply, xyz, grey)
    cap = imp.read_ply(ply, width=16, height=12)
    assert cap.points.shape == (12, 16, 3)
    assert cap.depth[0, 0] == 0 and cap.depth[-1, -1] == 0
    assert np.allclose(cap.depth[1:-1], xyz.reshape(12, 16, 3)[1:-1, :, 2], atol=1e-6)
    assert np.array_equal(cap.grey.ravel(), grey)
    fitted, rms = imp.fit_intrinsics(cap.points)
    assert np.allclose(fitted, k, atol=1e-3) and rms < 1e-3

    out = tmp_path / "cap.mcap"
    s = imp.import_ply([ply], out, width=16, height=12)
    assert s.frames == 1 and not s.labelled and s.invalid_fraction == pytest.approx(2 / 192)
    frames = list(iter_frames(out))
    assert len(frames) == 1
    f = frames[0]
    assert f.label is None and f.depth.dtype == np.float32
    assert f.depth[0, 0] == 0 and f.depth[1, 1] > 0
    assert f.info["fx"] == pytest.approx(k[0], abs=1e-3) and f.info["cy"] == pytest.approx(k[3], abs=1e-3)
    assert f.scene["params"]["file"] == "cap.ply"


def test_ply_grey_goes_to_mono8_topic(tmp_path):
    from mcap.reader import make_reader

    from edge import rosmsg

    xyz, grey = _synthetic_capture()
    ply = tmp_path / "cap.ply"
    _write_ply(ply, xyz, grey)
    out = tmp_path / "cap.mcap"
    imp.import_ply([ply], out, width=16, height=12)
    with open(out, "rb") as fh:
        msgs = [(c.topic, m) for _s, c, m in make_reader(fh).iter_messages(topics=[imp.TOPIC_MONO8, TOPIC_INFO])]
    topics = [t for t, _ in msgs]
    assert topics.count(imp.TOPIC_MONO8) == 1 and topics.count(TOPIC_INFO) == 1
    img = rosmsg.decode_image(next(m for t, m in msgs if t == imp.TOPIC_MONO8).data)
    assert img.encoding == "mono8"
    assert np.array_equal(rosmsg.image_to_array(img).ravel(), grey)


@pytest.mark.parametrize(
    "content, message",
    [
        ("hello\nworld\n", "not a PLY"),
        ("ply\nformat binary_little_endian 1.0\nelement vertex 4\nproperty float x\nend_header\n", "only ASCII PLY"),
        ("ply\nformat ascii 1.0\nelement vertex 192\nproperty float x\n", "end_header"),
        ("ply\nformat ascii 1.0\nelement vertex 5\nproperty float x\nproperty float y\nproperty float z\nend_header\n"
         + "0 0 1\n" * 5, "5 vertices; expected 192"),
        ("ply\nformat ascii 1.0\nelement vertex 192\nproperty float x\nproperty float y\nproperty float z\nend_header\n"
         + "0 0 1\n" * 100, "truncated"),
        ("ply\nformat ascii 1.0\nelement vertex 192\nproperty float x\nproperty float y\nend_header\n"
         + "0 0\n" * 192, r"lack properties \['z'\]"),
        ("ply\nformat ascii 1.0\nelement vertex 192\nproperty float x\nproperty float y\nproperty float z\nend_header\n"
         + "0 zero 1\n" * 192, "non-numeric"),
        ("ply\nformat ascii 1.0\nelement vertex 192\nproperty float x\nproperty float y\nproperty float z\nend_header\n"
         + "0 0\n" * 192, "more than the 768 bytes left"),
    ],
)  # fmt: skip
def test_malformed_ply_is_a_one_line_data_error(tmp_path, content, message):
    p = tmp_path / "bad.ply"
    p.write_text(content)
    with pytest.raises(DataError, match=message) as info:
        imp.read_ply(p, width=16, height=12)
    assert "\n" not in str(info.value)


def test_import_cli_errors_are_one_line(tmp_path, capsys):
    bad = tmp_path / "bad.ply"
    bad.write_text("not a ply\n")
    assert imp.import_main(["ply", str(bad), "--out", str(tmp_path / "o.mcap")]) == 2
    assert imp.import_main(["ply", str(tmp_path / "missing.ply"), "--out", str(tmp_path / "o.mcap")]) == 2
    assert imp.import_main(["blensor", str(tmp_path), "--out", str(tmp_path / "o.mcap")]) == 2
    assert imp.import_main(["ply", str(bad), "--out", str(tmp_path)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 4 and all(line.startswith("depthseg-sim import") for line in err)
    assert "not a PLY" in err[0] and "no such file" in err[1] and "scan_*.npy" in err[2] and "directory" in err[3]
    assert not (tmp_path / "o.mcap").exists()


def test_synthetic_blensor_scan(tmp_path):
    """A flat floor seen straight down: radial range grows off-centre, Z stays flat."""
    fx, fy, cx, cy = imp.blensor_intrinsics()
    v, u = np.mgrid[0:H, 0:W].astype(np.float64)
    norm = np.sqrt(1 + ((u - cx) / fx) ** 2 + ((v - cy) / fy) ** 2)
    radial = 0.3 * norm
    ids = np.full((H, W), 7.0)
    ids[80:90, 100:120] = 3.0
    radial[80:90, 100:120] = 0.25 * norm[80:90, 100:120]
    radial[0, 0] = 0.0  # no return
    # the paper's storage order: row.reshape(224, 171).T is the image
    np.save(tmp_path / "scan_0.npy", np.stack([radial.T.ravel(), ids.T.ravel()]))
    bad = tmp_path / "scan_1.npy"
    np.save(bad, np.zeros((2, 100)))
    with pytest.raises(DataError, match=r"shape \(2, 100\); expected \(2, 38304\)"):
        imp.read_blensor_scan(bad)
    bad.unlink()
    scan = imp.read_blensor_scan(tmp_path / "scan_0.npy")
    assert np.array_equal(scan.radial, radial)
    depth, label = imp.blensor_frame(scan, 7.0)
    floor = ids == 7.0
    floor[0, 0] = False
    assert depth[0, 0] == 0 and np.allclose(depth[floor], 0.3, atol=1e-6)
    assert np.allclose(depth[80:90, 100:120], 0.25, atol=1e-6)
    assert label.sum() == 200 and label[80:90, 100:120].all()
    # the ground covers the frame border
    assert imp.detect_background_id([scan]) == 7.0


# ---------------------------------------------------------------------------- real shared data


@pytest.fixture(scope="module")
def blensor_scans():
    _need(BLENSOR)
    return [imp.read_blensor_scan(f) for f in imp.find_inputs([BLENSOR], "scan_*.npy", "scans")]


def test_blensor_background_id_is_the_ground(blensor_scans):
    bg = imp.detect_background_id(blensor_scans)
    assert bg == float(np.unique(blensor_scans[0].ids)[0])  # scan_0 is background only
    assert int(bg).to_bytes(4, "little") == b"grou"  # the first four letters of "ground"
    # without the background-only scan, the border rule finds the same id
    assert imp.detect_background_id(blensor_scans[1:]) == bg


def test_blensor_import_shapes_labels_and_z(blensor_scans, tmp_path):
    out = tmp_path / "blensor.mcap"
    s = imp.import_blensor([BLENSOR], out)
    assert s.frames == len(blensor_scans) == 10 and s.labelled
    frames = list(iter_frames(out))
    assert [f.scene["params"]["file"] for f in frames] == [f"scan_{i}.npy" for i in range(10)]
    bg = s.extra["background_id"]
    fx, fy, cx, cy = imp.blensor_intrinsics()
    for f, scan in zip(frames, blensor_scans):
        assert f.depth.shape == (H, W) and f.label.shape == (H, W) and f.depth.dtype == np.float32
        assert np.array_equal(f.label, (scan.ids != bg).astype(np.uint8))
        assert f.info["fx"] == pytest.approx(fx) and f.info["cx"] == pytest.approx(cx)
        valid = f.depth > 0
        assert (f.depth[valid] <= scan.radial[valid] + 1e-6).all()
        # off-centre pixels: Z clearly below the range (the corner ray is 1.24x longer than Z)
        corner = np.sqrt(1 + (cx / fx) ** 2 + (cy / fy) ** 2)
        assert corner > 1.2 and f.depth[0, 0] == pytest.approx(scan.radial[0, 0] / corner, rel=1e-5)
        assert abs(f.depth[int(cy), int(cx)] - scan.radial[int(cy), int(cx)]) < 1e-4
    assert frames[0].label.sum() == 0
    assert all(f.label.sum() > 0 for f in frames[1:])


def test_blensor_background_scan_is_planar_in_z(blensor_scans):
    scan = blensor_scans[0]
    k = imp.blensor_intrinsics()
    depth, _ = imp.blensor_frame(scan, imp.detect_background_id(blensor_scans), k)
    everything = np.ones(depth.shape, bool)
    rms = _plane_rms(depth, k, everything)
    assert rms < 0.005  # BlenSor's own noise: sigma 4 mm along the ray
    # taking the radial range for Z bends the floor into a bowl: far from planar
    assert _plane_rms(scan.radial.astype(np.float32), k, everything) > 2 * rms


def test_royale_ply_import(tmp_path):
    _need(ROYALE)
    cap = imp.read_ply(ROYALE)
    assert cap.points.shape == (H, W, 3)
    invalid = ~cap.valid
    assert 0.01 < invalid.mean() < 0.10
    assert (cap.depth[invalid] == 0).all() and (cap.depth[~invalid] > 0.2).all()
    assert (cap.points[invalid] == 0).all()
    (fx, fy, cx, cy), rms = imp.fit_intrinsics(cap.points, cap.valid)
    # SENSOR.md: fitted fx ~ 202, fy ~ 205, cx ~ 116, cy ~ 88
    assert fx == pytest.approx(202, abs=3) and fy == pytest.approx(205, abs=3)
    assert cx == pytest.approx(116, abs=2) and cy == pytest.approx(88, abs=2)
    assert rms < 3.0
    out = tmp_path / "royale.mcap"
    assert imp.import_main(["ply", str(ROYALE), "--out", str(out), "--json"]) == 0
    (f,) = list(iter_frames(out))
    assert f.label is None and np.array_equal(f.depth, cap.depth)
    assert f.info["fx"] == pytest.approx(fx)


def test_ply_import_with_geometric_labels(tmp_path):
    """--label-above-plane: a box 3 cm above a 40 x 30 px floor is labelled, the floor is not."""
    w, h, k = 40, 30, (40.0, 42.0, 19.5, 14.5)
    fx, fy, cx, cy = k
    v, u = np.mgrid[0:h, 0:w].astype(np.float64)
    z = np.full((h, w), 0.3)
    box = (slice(10, 20), slice(12, 26))
    z[box] -= 0.03
    xyz = np.stack([(u - cx) / fx * z, (v - cy) / fy * z, z], axis=-1)
    ply = tmp_path / "cap.ply"
    _write_ply(ply, xyz.reshape(-1, 3), np.zeros(w * h, np.uint8))
    out = tmp_path / "cap.mcap"
    s = imp.import_ply([ply], out, width=w, height=h, label_above_plane_m=0.01)
    assert s.labelled and s.object_fraction == pytest.approx(140 / 1200, abs=0.01)
    f = next(iter(iter_frames(out)))
    expected = np.zeros((h, w), np.uint8)
    expected[box] = 1
    assert (f.label != expected).sum() <= 4  # the 3x3 median may round the box's corners
    assert "10 mm above the RANSAC floor plane" in f.scene["params"]["labels"]
