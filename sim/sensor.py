"""ToF sensor model: turn a clean ray-cast frame into what a pico flexx would output.

Why a model at all: the paper trained on BlenSor's Gaussian-only noise (sigma 4 mm) and its
network then failed on real pico flexx frames (section V.e): real frames have dead corners,
flying pixels at edges, multipath, noise that depends on range and brightness. Every
parameter below says which fact of ``shared/SENSOR.md`` (or of the real capture in
``shared/data/royale``) it comes from. It follows SENSOR.md "A model to implement":

1. Rays, r and Z: `sim.render`.
2. Amplitude ``A = albedo * cos(incidence) * |ray|^-4 * (r_ref / r)^2``, times a lens /
   illumination cone (see below), scaled by an auto-exposure gain so the frame's median
   amplitude is ~1 (Royale runs auto exposure; without it, thresholds would depend on the
   camera height). The gain is off by a random per-frame factor, as auto exposure is.
3. ``sigma_r = max(sigma_min, sigma_ref * sqrt(A_ref / A))`` per pixel. The noise is drawn iid,
   blurred 3x3 (Royale's 3x3 smoothing makes real noise spatially correlated) and scaled so the
   output standard deviation is ``sigma_r / smoothing`` (Royale: noise reduced ~2.5x).
4. Mixed pixels: edge pixels are supersampled by the renderer; the samples' returns are summed
   as phasors at the 60.24 MHz modulation frequency, so a pixel straddling an edge reads a
   range between the two surfaces, pulled towards the brighter one (a flying pixel).
   The complex return is then blurred with a small Gaussian point-spread function (lens blur
   and Royale's spatial filter), sigma drawn per frame from 0-0.4 px. An earlier fit (0.7-1.1 px,
   matching "46 % of the pixels within 2 px of a depth step read in between") gave 189 +- 135
   sharp-edge pixels (4-neighbour step > 18 mm) per frame against 1240 in the real capture, and
   a model trained on it painted a 1-2 px halo around objects on real and BlenSor frames
   (issue 9). With 0-0.4 px, 8-12 objects at 30 cm (``tools/sim_vs_real.py --config``): 794 +-
   224 sharp-edge pixels and 0.175 invalid edge pixels per valid edge pixel (real: 0.173); 0 px
   is BlenSor's crisp edge.
   Multipath: floor pixels near tall objects read long (or short) by up to ~1 cm, in proportion
   to the object height around them (a blurred height map).
5. Invalid: amplitude below ``amplitude_min`` (the corners, dark or grazing surfaces), above
   ``amplitude_max`` (saturation, bright surfaces up close), outside the use case's range, the
   Royale flying-pixel rule (differs from both horizontal or both vertical neighbours by more
   than 18 mm; ``flying_miss_prob`` of them survive, as 0.48 % of the real capture's edge pixels
   do: 0.03 brings the simulator to 0.48 %, ``tools/sim_vs_real.py``), and random dead pixels.
6. Output Z = r / |ray|, 0 for invalid (the ROS driver convention). The clean Z is kept apart.

The corner cone: the real capture's invalid corners start sharply at 31-34 deg off axis
(measured on shared/data/royale with the datasheet intrinsics: 2 % invalid at 31-32 deg, 69 %
at 33-34, 98 % at 34-35; about 3 % of the frame). cos^4 vignetting alone is far too gentle
for that, so the amplitude is multiplied by a logistic cut-off at ``cone_half_angle_deg``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache
from typing import Any

import numpy as np

from sim.render import FLOOR_ID, NO_HIT, RayGrid, RenderResult
from sim.scene import _to_dict, check_fields, check_number, check_range, config_from_dict, omit_neutral

__all__ = ["SensorConfig", "SensorOutput", "FrameDraw", "draw_frame_params", "apply_sensor"]

_C = 299_792_458.0


@dataclass(frozen=True)
class SensorConfig:
    """Every knob of the ToF model. Ranges are drawn per frame (or per object for albedo)."""

    # 2. amplitude
    albedo_floor: tuple[float, float] = (0.35, 0.85)  # NIR reflectance of the floor, per frame
    albedo_object: tuple[float, float] = (0.1, 1.0)  # per object; dark objects get noisy, even holes (real capture)
    range_ref_m: float = 0.30  # amplitude reference distance (camera ~30 cm above the table)
    vignetting_power: float = 4.0  # |ray|^-4 (SENSOR.md step 2)
    cone_half_angle_deg: tuple[float, float] = (31.5, 33.0)  # corner cut-off, per frame (fitted, see above)
    cone_width_deg: float = 0.6  # logistic width of the cut-off (real capture: 31 -> 35 deg)
    exposure: tuple[float, float] = (0.7, 1.4)  # auto-exposure error factor, log-uniform per frame
    amplitude_noise: float = 0.1  # relative shot noise on A (ragged invalid boundaries)
    # 3. range noise
    sigma_ref_m: float = 0.003  # raw noise at A_ref (SENSOR.md: ~3 mm at 30 cm)
    sigma_min_m: float = 0.0005  # SENSOR.md: sigma_min ~0.5 mm
    amplitude_ref: float = 1.0  # the median amplitude after auto exposure
    noise_scale: tuple[float, float] = (0.7, 1.4)  # per-frame noise level factor
    smoothing: float = 2.5  # Royale's 3x3 filter reduces noise ~2.5x (SENSOR.md)
    correlated: bool = True  # noise blurred 3x3, as after Royale's filter
    white_noise_prob: float = 0.0  # share of frames with white (uncorrelated) noise, as BlenSor's
    # 4. mixed pixels and multipath
    mixed_pixels: bool = True
    psf_sigma_px: tuple[float, float] = (0.0, 0.4)  # per frame; crisp (BlenSor) to the real sensor (fitted, see above)
    modulation_hz: float = 60.24e6  # MODE_5_45FPS_500 (SENSOR.md)
    multipath_gain: tuple[float, float] = (-0.03, 0.12)  # per frame: metres of bias per metre of nearby height
    multipath_radius_m: float = 0.04
    multipath_max_m: float = 0.01  # SENSOR.md: up to ~1 cm
    # 5. invalid pixels
    amplitude_min: float = 0.12  # relative to the median (corners, dark or grazing surfaces)
    amplitude_max: float = 12.0  # saturation, relative to the median
    flying_filter: bool = True
    flying_threshold_m: float = 0.018  # Royale flying-pixel filter (SENSOR.md)
    # share of the pixels the flying-pixel rule flags that the filter lets through anyway: the real
    # capture keeps 0.48 % of its sharp-edge pixels as flying pixels; a perfect filter keeps none
    flying_miss_prob: float = 0.0
    dead_pixel_fraction: float = 5e-4
    min_range_m: float = 0.10  # MODE_5_45FPS_500: 0.1 - 1.0 m
    max_range_m: float = 1.0

    def __post_init__(self) -> None:
        check_fields(self, "sensor")
        check_range("sensor.albedo_floor", self.albedo_floor, 1e-3, 10.0)
        check_range("sensor.albedo_object", self.albedo_object, 1e-3, 10.0)
        check_number("sensor.range_ref_m", self.range_ref_m, 1e-3)
        check_number("sensor.vignetting_power", self.vignetting_power, 0.0, 20.0)
        check_range("sensor.cone_half_angle_deg", self.cone_half_angle_deg, 1.0, 90.0)
        check_number("sensor.cone_width_deg", self.cone_width_deg, 1e-3, 45.0)
        check_range("sensor.exposure", self.exposure, 1e-3, 1e3)
        check_number("sensor.amplitude_noise", self.amplitude_noise, 0.0, 10.0)
        check_number("sensor.sigma_ref_m", self.sigma_ref_m, 0.0, 1.0)
        check_number("sensor.sigma_min_m", self.sigma_min_m, 0.0, 1.0)
        check_number("sensor.amplitude_ref", self.amplitude_ref, 1e-6)
        check_range("sensor.noise_scale", self.noise_scale, 0.0, 100.0)
        check_number("sensor.smoothing", self.smoothing, 0.1, 100.0)
        check_number("sensor.white_noise_prob", self.white_noise_prob, 0.0, 1.0)
        check_range("sensor.psf_sigma_px", self.psf_sigma_px, 0.0, 10.0)
        check_number("sensor.modulation_hz", self.modulation_hz, 1e5, 1e10)
        check_range("sensor.multipath_gain", self.multipath_gain, -10.0, 10.0)
        check_number("sensor.multipath_radius_m", self.multipath_radius_m, 0.0, 1.0)
        check_number("sensor.multipath_max_m", self.multipath_max_m, 0.0, 1.0)
        check_number("sensor.amplitude_min", self.amplitude_min, 0.0)
        check_number("sensor.amplitude_max", self.amplitude_max, 0.0)
        check_number("sensor.flying_threshold_m", self.flying_threshold_m, 0.0)
        check_number("sensor.flying_miss_prob", self.flying_miss_prob, 0.0, 1.0)
        check_number("sensor.dead_pixel_fraction", self.dead_pixel_fraction, 0.0, 1.0)
        check_range("sensor.range_m", (self.min_range_m, self.max_range_m), 0.0, 100.0)

    def to_dict(self) -> dict[str, Any]:
        """All fields; ``flying_miss_prob`` only when set, so configs from before it keep their digest."""
        return omit_neutral(_to_dict(self), {"flying_miss_prob": 0.0})

    @classmethod
    def from_dict(cls, d: dict[str, Any] | None) -> SensorConfig:
        return config_from_dict(cls, d, "sensor")

    @classmethod
    def ideal(cls) -> SensorConfig:
        """No noise, no invalid pixels, no mixing: output Z equals the clean Z."""
        return cls(
            sigma_ref_m=0.0,
            sigma_min_m=0.0,
            mixed_pixels=False,
            psf_sigma_px=(0.0, 0.0),
            multipath_gain=(0.0, 0.0),
            amplitude_noise=0.0,
            amplitude_min=0.0,
            amplitude_max=1e9,
            flying_filter=False,
            dead_pixel_fraction=0.0,
            cone_half_angle_deg=(90.0, 90.0),
            min_range_m=0.0,
            max_range_m=100.0,
        )


@dataclass
class FrameDraw:
    """The per-frame random sensor state (goes into the scene JSON)."""

    albedo_floor: float
    albedo_objects: np.ndarray
    exposure: float
    noise_scale: float
    multipath_gain: float
    cone_half_angle_deg: float
    psf_sigma_px: float = 0.0
    white_noise: bool = False

    def to_params(self) -> dict[str, Any]:
        return {
            "albedo_floor": round(self.albedo_floor, 5),
            "albedo_objects": self.albedo_objects.round(5).tolist(),
            "exposure": round(self.exposure, 5),
            "noise_scale": round(self.noise_scale, 5),
            "multipath_gain": round(self.multipath_gain, 5),
            "cone_half_angle_deg": round(self.cone_half_angle_deg, 4),
            "psf_sigma_px": round(self.psf_sigma_px, 4),
            "white_noise": self.white_noise,
        }


def _u(rng: np.random.Generator, r: tuple[float, float]) -> float:
    return float(rng.uniform(r[0], r[1])) if r[1] > r[0] else float(r[0])


def draw_frame_params(rng: np.random.Generator, cfg: SensorConfig, n_objects: int) -> FrameDraw:
    lo, hi = cfg.exposure
    return FrameDraw(
        albedo_floor=_u(rng, cfg.albedo_floor),
        albedo_objects=rng.uniform(cfg.albedo_object[0], cfg.albedo_object[1], size=n_objects),
        exposure=float(math.exp(rng.uniform(math.log(lo), math.log(hi)))) if hi > lo else float(lo),
        noise_scale=_u(rng, cfg.noise_scale),
        multipath_gain=_u(rng, cfg.multipath_gain),
        cone_half_angle_deg=_u(rng, cfg.cone_half_angle_deg),
        psf_sigma_px=_u(rng, cfg.psf_sigma_px),
        # drawn only when enabled, so that default frames keep their random stream
        white_noise=bool(cfg.white_noise_prob > 0 and rng.random() < cfg.white_noise_prob),
    )


@dataclass
class SensorOutput:
    depth: np.ndarray  # (H, W) float32 Z, metres, 0 = invalid
    valid: np.ndarray  # (H, W) bool
    amplitude: np.ndarray  # (H, W) float32, relative (median ~1)


def _box3(x: np.ndarray) -> np.ndarray:
    import cv2

    return cv2.blur(x, (3, 3), borderType=cv2.BORDER_REFLECT)


def _blur_wide(x: np.ndarray, radius_px: float) -> np.ndarray:
    """Cheap wide smoothing: two box passes (close to a Gaussian), on a 4x smaller image."""
    import cv2

    h, w = x.shape
    small = cv2.resize(x, (max(w // 4, 1), max(h // 4, 1)), interpolation=cv2.INTER_AREA)
    k = max(int(round(radius_px / 4)) * 2 + 1, 1)
    small = cv2.blur(cv2.blur(small, (k, k)), (k, k))
    return cv2.resize(small, (w, h), interpolation=cv2.INTER_LINEAR)


def _psf(r: np.ndarray, amp: np.ndarray, hit: np.ndarray, sigma_px: float, k: float) -> tuple[np.ndarray, np.ndarray]:
    """Blur the complex return A * exp(i k r) with a Gaussian point-spread function.

    Neighbouring surfaces mix the way a ToF pixel mixes light: as phasors, weighted by their
    amplitude, so a pixel next to an edge reads in between, pulled towards the brighter side.
    Phases are taken relative to the median range, far from the 2.49 m wrap-around.
    """
    import cv2

    r0 = float(np.median(r[hit][::7])) if hit.any() else 0.0
    ph = k * (r - r0)
    a = np.where(hit, amp, 0.0).astype(np.float32)
    re = cv2.GaussianBlur((a * np.cos(ph)).astype(np.float32), (0, 0), sigma_px, borderType=cv2.BORDER_REFLECT)
    im = cv2.GaussianBlur((a * np.sin(ph)).astype(np.float32), (0, 0), sigma_px, borderType=cv2.BORDER_REFLECT)
    amp_b = np.hypot(re, im)
    ok = hit & (amp_b > 0)
    r_b = np.where(ok, r0 + np.arctan2(im, re) / k, r).astype(np.float32)
    return r_b, np.where(hit, amp_b, amp).astype(np.float32)


@lru_cache(maxsize=16)
def _off_axis_deg(grid: RayGrid) -> np.ndarray:
    """Angle of each pixel's ray to the optical axis (cached per ray grid, i.e. per camera)."""
    theta = np.degrees(np.arctan(np.sqrt(np.maximum(grid.norm.astype(np.float64) ** 2 - 1.0, 0.0))))
    theta.flags.writeable = False
    return theta


@lru_cache(maxsize=16)
def _vignetting(grid: RayGrid, power: float) -> np.ndarray:
    v = grid.norm ** (-power)
    v.flags.writeable = False
    return v


def _cone(grid: RayGrid, half_angle_deg: float, width_deg: float) -> np.ndarray:
    theta = _off_axis_deg(grid)
    x = np.clip((theta - half_angle_deg) / width_deg, -50, 50)
    return (1.0 / (1.0 + np.exp(x))).astype(np.float32)


def apply_sensor(
    rr: RenderResult,
    grid: RayGrid,
    fx: float,
    camera_height: float,
    draw: FrameDraw,
    cfg: SensorConfig,
    rng: np.random.Generator,
) -> SensorOutput:
    """The noisy Z frame (0 = invalid) from a clean render; randomness only from ``rng``."""
    h, w = rr.r.shape
    # albedo lookup by id: index 0 = NO_HIT, 1 = floor, k + 2 = object k
    lut = np.concatenate([[0.0, draw.albedo_floor], draw.albedo_objects]).astype(np.float32)
    hit = rr.ids != NO_HIT
    r = rr.r
    safe_r = np.where(hit, np.maximum(r, 1e-4), 1.0)
    spatial = _vignetting(grid, cfg.vignetting_power) * _cone(grid, draw.cone_half_angle_deg, cfg.cone_width_deg)
    amp = lut[rr.ids + 1] * rr.cos_inc * spatial * (cfg.range_ref_m / safe_r) ** 2
    med = float(np.median(amp[hit][::7])) if hit.any() else 1.0
    gain = draw.exposure / max(med, 1e-12)
    amp = (amp * gain).astype(np.float32)

    r_meas = r.astype(np.float32).copy()
    if cfg.mixed_pixels and len(rr.edge):
        s = rr.sub_r.shape[1]
        sub_spatial = np.repeat(spatial.ravel()[rr.edge][:, None], s, axis=1)
        sub_hit = rr.sub_ids != NO_HIT
        sub_amp = lut[rr.sub_ids + 1] * rr.sub_cos * sub_spatial * (cfg.range_ref_m / np.maximum(rr.sub_r, 1e-4)) ** 2
        sub_amp = np.where(sub_hit, sub_amp * gain, 0.0)
        k = 4.0 * math.pi * cfg.modulation_hz / _C  # phase per metre of range
        r0 = r.ravel()[rr.edge]
        dphi = k * (rr.sub_r - r0[:, None])
        re = (sub_amp * np.cos(dphi)).sum(1)
        im = (sub_amp * np.sin(dphi)).sum(1)
        a_mix = np.hypot(re, im) / s
        ok = a_mix > 0
        flat_r = r_meas.ravel()
        flat_a = amp.ravel()
        idx = rr.edge[ok]
        flat_r[idx] = (r0[ok] + np.arctan2(im[ok], re[ok]) / k).astype(np.float32)
        flat_a[idx] = a_mix[ok]

    floor = rr.ids == FLOOR_ID
    if draw.multipath_gain != 0.0 and cfg.multipath_max_m > 0 and (rr.ids > FLOOR_ID).any():
        heights = np.where(rr.ids > FLOOR_ID, rr.height, 0.0).astype(np.float32)
        radius_px = fx * cfg.multipath_radius_m / max(camera_height, 1e-3)
        bias = np.clip(draw.multipath_gain * _blur_wide(heights, radius_px), -cfg.multipath_max_m, cfg.multipath_max_m)
        r_meas = np.where(floor, r_meas + bias, r_meas)

    if draw.psf_sigma_px > 0:
        r_meas, amp = _psf(r_meas, amp, hit, draw.psf_sigma_px, 4.0 * math.pi * cfg.modulation_hz / _C)

    noise = rng.standard_normal((h, w), dtype=np.float32)
    if cfg.correlated and not draw.white_noise:
        noise = _box3(noise) * 3.0  # unit variance again, correlated over 3x3
    sigma = np.maximum(
        cfg.sigma_min_m, cfg.sigma_ref_m * draw.noise_scale * np.sqrt(cfg.amplitude_ref / np.maximum(amp, 1e-6))
    ) / cfg.smoothing
    if cfg.sigma_ref_m > 0 or cfg.sigma_min_m > 0:
        r_meas = r_meas + noise * sigma.astype(np.float32)

    amp_meas = amp
    if cfg.amplitude_noise > 0:
        amp_meas = amp * (1.0 + cfg.amplitude_noise * rng.standard_normal((h, w), dtype=np.float32))
    valid = hit & (amp_meas >= cfg.amplitude_min) & (amp_meas <= cfg.amplitude_max)
    valid &= (r_meas >= cfg.min_range_m) & (r_meas <= cfg.max_range_m)
    if cfg.flying_filter:
        t = cfg.flying_threshold_m
        rm = np.where(valid, r_meas, np.nan)  # Royale compares with valid neighbours only
        with np.errstate(invalid="ignore"):
            dl = np.abs(rm[:, 1:-1] - rm[:, :-2]) > t
            dr = np.abs(rm[:, 1:-1] - rm[:, 2:]) > t
            du = np.abs(rm[1:-1, :] - rm[:-2, :]) > t
            dd = np.abs(rm[1:-1, :] - rm[2:, :]) > t
        fly = np.zeros((h, w), dtype=bool)
        fly[:, 1:-1] |= dl & dr
        fly[1:-1, :] |= du & dd
        fly &= r_meas < 1.0
        if cfg.flying_miss_prob > 0:  # drawn only when enabled: default frames keep their random stream
            fly &= rng.random((h, w), dtype=np.float32) >= cfg.flying_miss_prob
        valid &= ~fly
    if cfg.dead_pixel_fraction > 0:
        n_dead = int(rng.binomial(h * w, cfg.dead_pixel_fraction))
        valid.ravel()[rng.integers(0, h * w, size=n_dead)] = False
    depth = np.where(valid, r_meas / grid.norm, 0.0).astype(np.float32)
    return SensorOutput(depth=depth, valid=valid, amplitude=amp_meas.astype(np.float32))
