"""Labels and clean depth on scenes of known geometry, checked against independent geometry."""

from __future__ import annotations

import math

import numpy as np
import pytest

from sim.render import Camera, ray_grid, render
from sim.shapes import make_shape

CAM = Camera()  # datasheet pinhole: 62 x 45 deg


def _box_world(size, centre, yaw):
    """Vertices/triangles of a box (via the procedural mesh code path) placed in the world."""
    rng = np.random.default_rng(0)
    shape = make_shape("box", rng, 0.05, 0.01)  # only its triangle layout is used
    unit = np.sign(shape.vertices)  # +-1 corners
    v = unit * (np.asarray(size) / 2)
    c, s = math.cos(yaw), math.sin(yaw)
    rz = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])
    return (v @ rz.T + centre).astype(np.float32), shape.triangles


def _expected_mask(size, centre, yaw, cam_h, cam_yaw):
    """Independent ray/box slab test at every pixel centre (no open3d involved)."""
    v, u = np.mgrid[0 : CAM.height, 0 : CAM.width].astype(float)
    d_cam = np.stack([(u - CAM.cx) / CAM.fx, (v - CAM.cy) / CAM.fy, np.ones_like(u)], -1)
    c, s = math.cos(cam_yaw), math.sin(cam_yaw)
    r_wc = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]]) @ np.diag([1.0, -1.0, -1.0])
    d = d_cam @ r_wc.T
    o = np.array([0.0, 0.0, cam_h])
    cb, sb = math.cos(yaw), math.sin(yaw)
    to_box = np.array([[cb, sb, 0], [-sb, cb, 0], [0, 0, 1]])  # inverse yaw
    ob = to_box @ (o - centre)
    db = d @ to_box.T
    half = np.asarray(size) / 2
    with np.errstate(divide="ignore", invalid="ignore"):
        t1 = (-half - ob) / db
        t2 = (half - ob) / db
    tmin = np.nanmax(np.minimum(t1, t2), axis=-1)
    tmax = np.nanmin(np.maximum(t1, t2), axis=-1)
    return (tmax >= tmin) & (tmax > 0)


def _ring(mask):
    import cv2

    k = np.ones((3, 3), np.uint8)
    m = mask.astype(np.uint8)
    return (cv2.dilate(m, k) - cv2.erode(m, k)).astype(bool)


def test_box_straight_below_has_the_analytic_footprint():
    size, h = (0.06, 0.04, 0.03), 0.30
    mesh = _box_world(size, np.array([0.0, 0.0, size[2] / 2]), 0.0)
    r_wc = np.diag([1.0, -1.0, -1.0])
    rr = render([mesh], CAM, r_wc, np.array([0, 0, h]), supersample=False)
    lab = rr.label
    rows, cols = np.nonzero(lab)
    dist = h - size[2]  # camera to the top face
    # width and height in pixels: f * size / distance, within one pixel
    assert cols.max() - cols.min() + 1 == pytest.approx(CAM.fx * size[0] / dist, abs=1.0)
    assert rows.max() - rows.min() + 1 == pytest.approx(CAM.fy * size[1] / dist, abs=1.0)
    assert (cols.max() + cols.min()) / 2 == pytest.approx(CAM.cx, abs=0.5)
    np.testing.assert_allclose(rr.z[lab == 1], dist, atol=1e-5)  # clean Z of the top face
    # the floor: Z = camera height everywhere else
    np.testing.assert_allclose(rr.z[lab == 0], h, atol=1e-5)
    np.testing.assert_allclose(rr.r, rr.z * ray_grid(CAM).norm, rtol=1e-6)


@pytest.mark.parametrize("yaw,cam_yaw,centre", [(0.5, 0.0, (0.03, -0.02)), (1.2, 2.0, (-0.05, 0.04))])
def test_rotated_offset_box_matches_independent_ray_test(yaw, cam_yaw, centre):
    size, h = (0.08, 0.03, 0.05), 0.25
    c = np.array([centre[0], centre[1], size[2] / 2])
    mesh = _box_world(size, c, yaw)
    c_, s_ = math.cos(cam_yaw), math.sin(cam_yaw)
    r_wc = np.array([[c_, -s_, 0], [s_, c_, 0], [0, 0, 1]]) @ np.diag([1.0, -1.0, -1.0])
    rr = render([mesh], CAM, r_wc, np.array([0, 0, h]), supersample=False)
    expected = _expected_mask(size, c, yaw, h, cam_yaw)
    wrong = rr.label.astype(bool) != expected
    assert expected.sum() > 500
    # any disagreement lies on the one-pixel boundary ring, and is rare even there
    assert not np.any(wrong & ~_ring(expected))
    assert wrong.sum() <= 0.02 * _ring(expected).sum()


def test_supersampled_pixels_sit_on_edges_only():
    size, h = (0.06, 0.06, 0.04), 0.30
    mesh = _box_world(size, np.array([0.0, 0.0, 0.02]), 0.3)
    rr = render([mesh], CAM, np.diag([1.0, -1.0, -1.0]), np.array([0, 0, h]))
    edge = np.zeros(CAM.height * CAM.width, bool)
    edge[rr.edge] = True
    assert edge.sum() > 0
    assert np.all(_ring(rr.label.astype(bool)).ravel()[edge])
    assert rr.sub_r.shape == (len(rr.edge), 4)


def test_distorted_rays_project_back_to_their_pixels():
    import cv2

    cam = Camera(fx=211.95, fy=211.95, cx=115.65, cy=87.13, distortion=(0.5786, -5.7317, 0.0, 0.0, 10.0098))
    g = ray_grid(cam)
    pts = g.dirs.reshape(-1, 3).astype(np.float64)
    k = np.array([[cam.fx, 0, cam.cx], [0, cam.fy, cam.cy], [0, 0, 1]])
    proj, _ = cv2.projectPoints(pts, np.zeros(3), np.zeros(3), k, np.array(cam.distortion))
    v, u = np.mgrid[0 : cam.height, 0 : cam.width]
    err = np.hypot(proj[:, 0, 0] - u.ravel(), proj[:, 0, 1] - v.ravel())
    # the strong TOF-VIO distortion does not invert well in the extreme corners (dead anyway)
    assert np.median(err) < 1e-3 and np.percentile(err, 95) < 0.05


# ----------------------------------------------------------------------------- label_min_height_m


def _ids_heights():
    """A 5 cm box (id 1) whose lowest 4 mm show as a 2 px base ring, and a 3 mm plate (id 2)."""
    from sim.render import RenderResult

    h, w = 40, 60
    ids = np.zeros((h, w), np.int32)
    height = np.zeros((h, w), np.float32)
    ids[8:20, 8:20], height[8:20, 8:20] = 1, 0.002  # the box's base (2 mm), seen beside its side
    ids[10:18, 10:18], height[10:18, 10:18] = 1, 0.050  # its top and upper side
    ids[25:30, 30:50], height[25:30, 30:50] = 2, 0.003  # a flat plate
    empty = np.zeros((0, 4))
    return RenderResult(z=np.full((h, w), 0.3, np.float32), r=np.full((h, w), 0.3, np.float32), ids=ids,
                        cos_inc=np.ones((h, w), np.float32), height=height, edge=np.zeros(0, np.int64),
                        sub_r=empty, sub_ids=empty.astype(np.int32), sub_cos=empty)


def test_labels_above_a_line_call_the_base_of_tall_objects_table_and_keep_thin_objects_whole():
    rr = _ids_heights()
    assert np.array_equal(rr.label_above(0.0), rr.label)
    lab = rr.label_above(0.010)
    assert lab[8:20, 8:20].sum() == 64 and lab[10:18, 10:18].all()  # the base ring is table, the box above it object
    assert lab[25:30, 30:50].all()  # the plate never reaches 10 mm: object whole
    assert not (lab.astype(bool) & ~rr.label.astype(bool)).any()  # only object pixels ever change


def test_the_line_is_measured_from_a_curved_table_top():
    from sim.render import Support

    box, tris = _box_world((0.04, 0.04, 0.004), (0.0, 0.0, 0.0), 0.0)  # a 4 mm plate centred on the apex
    rot = np.diag([1.0, -1.0, -1.0])
    flat = render([(box + np.array([0, 0, 0.002], np.float32), tris)], CAM, rot, np.array([0.0, 0.0, 0.3]))
    curved = render([(box + np.array([0.12, 0, 0.002 + 0.5 * 0.12**2], np.float32), tris)], CAM, rot,
                    np.array([0.0, 0.0, 0.3]), support=Support(curvature=0.5))
    assert curved.height[curved.ids == 1].max() > 0.011  # 7 mm of bowl under it: over the line from the floor
    for rr in (flat, curved):  # but over the table top under each hit it stays under 9 mm: a thin object
        assert rr.above_support[rr.ids == 1].max() < 0.009
        assert np.array_equal(rr.label_above(0.010), rr.label) and rr.label.sum() > 50


def test_a_label_line_changes_labels_only_and_only_when_asked():
    from sim.generate import SimConfig, generate_frame

    plain = SimConfig.from_dict({"scene": {"n_objects": [3, 5]}})
    ruled = SimConfig.from_dict({"scene": {"n_objects": [3, 5]}, "label_min_height_m": 0.01})
    assert "label_min_height_m" not in plain.to_dict() and SimConfig().digest() == SimConfig.from_dict({}).digest()
    assert SimConfig.from_dict(ruled.to_dict()).digest() == ruled.digest() != plain.digest()
    a, b = generate_frame(1, 7, plain), generate_frame(1, 7, ruled)
    assert np.array_equal(a.depth, b.depth) and np.array_equal(a.clean, b.clean)
    assert not (b.label & ~a.label).any() and 0 < b.label.sum() < a.label.sum()
