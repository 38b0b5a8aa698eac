"""The classical alternative a user would try first: fit the table plane, call anything above it object.

Why it is here: a learned model is only worth shipping if it beats this. Per frame:
1. back-project the valid pixels with the frame's intrinsics (its CameraInfo when the recording
   has one, else the model's sensor; lens distortion is undone with OpenCV when given);
2. fit the dominant plane with open3d's RANSAC ``segment_plane`` (seeded, so reruns agree),
   then refine it by least squares on the RANSAC inliers;
3. orient the normal towards the camera, smooth the signed height map with a 3 x 3 median
   (ToF noise is per pixel; a median is the first denoiser a user reaches for, and without it
   2-sigma noise alone flags ~2 % of the floor), and call a pixel object when its height above
   the plane exceeds ``height_threshold_m`` (8 mm by default, twice BlenSor's noise sigma).

The signed height (metres) minus the threshold is also exposed as a logit-like score
(`PlaneBaseline.scores`): > 0 means object, so threshold tuning can use it for pseudo-labels.
It fails where the paper's network also struggles (flat, low objects) and wherever the
biggest plane is not the table (a large box top seen from above). Torch-free.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache
from typing import Any

import numpy as np

from edge.errors import ConfigError, DataError
from edge.meta import SensorSpec
from edge.preprocess import valid_mask

__all__ = ["Intrinsics", "PlaneBaseline", "intrinsics_for", "back_project"]

MIN_POINTS = 50  # fewer valid pixels than this: no plane worth fitting, all background


@dataclass(frozen=True)
class Intrinsics:
    fx: float
    fy: float
    cx: float
    cy: float
    distortion: tuple[float, ...] = ()


def intrinsics_for(shape: tuple[int, int], info: dict[str, Any] | None = None, sensor: SensorSpec | None = None) -> Intrinsics:
    """Intrinsics for a frame: its CameraInfo if present, else the sensor's (rescaled to the frame size).

    Rescaling keeps the field of view when a frame was resized (e.g. small test frames).
    """
    h, w = shape
    if info is not None and all(k in info for k in ("fx", "fy", "cx", "cy")) and info["fx"] > 0 and info["fy"] > 0:
        ih, iw = int(info.get("height") or h), int(info.get("width") or w)
        if (ih, iw) != (h, w):
            raise DataError(f"camera_info is for {iw}x{ih} frames but the depth frame is {w}x{h}")
        d = tuple(float(v) for v in info.get("d") or ())
        return Intrinsics(float(info["fx"]), float(info["fy"]), float(info["cx"]), float(info["cy"]), d)
    s = sensor or SensorSpec()
    native = (s.height, s.width) == (h, w)
    return Intrinsics(*s.intrinsics_for_size(h, w), tuple(s.distortion) if native else ())


@lru_cache(maxsize=8)
def _rays(h: int, w: int, k: Intrinsics) -> tuple[np.ndarray, np.ndarray]:
    """Normalised image coordinates (xn, yn) per pixel, H x W each, distortion removed."""
    v, u = np.mgrid[0:h, 0:w].astype(np.float64)
    if any(abs(c) > 0 for c in k.distortion):
        import cv2

        cam = np.array([[k.fx, 0, k.cx], [0, k.fy, k.cy], [0, 0, 1]], np.float64)
        pts = np.stack([u.ravel(), v.ravel()], axis=1)[:, None, :]
        und = cv2.undistortPoints(pts, cam, np.asarray(k.distortion, np.float64)).reshape(h, w, 2)
        xn, yn = und[..., 0], und[..., 1]
    else:
        xn, yn = (u - k.cx) / k.fx, (v - k.cy) / k.fy
    xn.setflags(write=False)
    yn.setflags(write=False)
    return xn, yn


def back_project(depth: np.ndarray, k: Intrinsics, valid: np.ndarray | None = None) -> np.ndarray:
    """N x 3 camera-frame points (metres) of the valid pixels of a Z-depth frame, row-major order."""
    depth = np.asarray(depth)
    if valid is None:
        valid = valid_mask(depth)
    xn, yn = _rays(depth.shape[0], depth.shape[1], k)
    z = depth[valid].astype(np.float64)
    return np.stack([xn[valid] * z, yn[valid] * z, z], axis=1)


@dataclass(frozen=True)
class PlaneBaseline:
    """RANSAC floor plane + height threshold; every parameter is a knob a user may turn."""

    height_threshold_m: float = 0.008
    distance_threshold_m: float = 0.005  # RANSAC inlier band (about BlenSor's noise sigma)
    iterations: int = 500
    seed: int = 0
    median_px: int = 3  # median filter on the height map: 0 (off), 3 or 5

    def __post_init__(self) -> None:
        if not self.height_threshold_m > 0:
            raise ConfigError(f"height threshold must be > 0 m, got {self.height_threshold_m}")
        if not self.distance_threshold_m > 0:
            raise ConfigError(f"RANSAC distance threshold must be > 0 m, got {self.distance_threshold_m}")
        if self.iterations < 1:
            raise ConfigError(f"RANSAC iterations must be >= 1, got {self.iterations}")
        if self.median_px not in (0, 3, 5):
            raise ConfigError(f"median filter size must be 0 (off), 3 or 5 pixels, got {self.median_px}")

    def fit_plane(self, points: np.ndarray) -> np.ndarray | None:
        """(a, b, c, d) with unit normal pointing to the camera (origin above the plane); None if too few points."""
        if len(points) < MIN_POINTS:
            return None
        import open3d as o3d

        pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points))
        # open3d's RANSAC draws from its own global generator: re-seed for every frame so a
        # frame's result does not depend on which frames came before it. Its multi-threaded
        # RANSAC is not reproducible even when seeded (threads race for the generator: 4-10
        # distinct planes in 15 reruns of the 9 BlenSor scans here), so it runs on one thread.
        prev_threads = o3d.utility.get_max_threads()
        o3d.utility.set_max_threads(1)
        try:
            o3d.utility.random.seed(int(self.seed))
            model, inliers = pcd.segment_plane(
                distance_threshold=float(self.distance_threshold_m), ransac_n=3, num_iterations=int(self.iterations)
            )
        finally:
            o3d.utility.set_max_threads(prev_threads)
        plane = np.asarray(model, dtype=np.float64)
        if len(inliers) >= 3:
            inl = points[np.asarray(inliers)]
            centroid = inl.mean(axis=0)
            _, _, vt = np.linalg.svd(inl - centroid, full_matrices=False)
            n = vt[2]
            plane = np.array([n[0], n[1], n[2], -float(n @ centroid)])
        norm = float(np.linalg.norm(plane[:3]))
        if not np.isfinite(norm) or norm == 0:
            return None
        plane = plane / norm
        if plane[3] < 0:  # the camera (origin) must be on the positive side
            plane = -plane
        return plane

    def heights(self, depth: np.ndarray, k: Intrinsics) -> np.ndarray:
        """Signed height above the fitted plane per pixel (metres, float32, median-smoothed); 0 where invalid.

        Invalid pixels enter the median as height 0 (on the plane), which only biases pixels
        bordering invalid regions towards background.
        """
        depth = np.asarray(depth)
        if depth.ndim != 2:
            raise DataError(f"a depth frame must be 2-D (H x W), got shape {depth.shape}")
        valid = valid_mask(depth)
        out = np.zeros(depth.shape, np.float32)
        pts = back_project(depth, k, valid)
        plane = self.fit_plane(pts)
        if plane is None:
            return out
        out[valid] = (pts @ plane[:3] + plane[3]).astype(np.float32)
        if self.median_px:
            import cv2

            out = cv2.medianBlur(out, self.median_px)
            out[~valid] = 0.0
        return out

    def scores(self, depth: np.ndarray, k: Intrinsics) -> np.ndarray:
        """Logit-like score: height above the plane minus the threshold (m); > 0 means object."""
        s = self.heights(depth, k) - np.float32(self.height_threshold_m)
        s[~valid_mask(depth)] = -np.float32(self.height_threshold_m)
        return s

    def predict(self, depth: np.ndarray, k: Intrinsics) -> np.ndarray:
        """Boolean object mask (invalid pixels are background)."""
        return self.heights(depth, k) > self.height_threshold_m
