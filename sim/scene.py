"""Scene parameters: the paper's Table I as defaults, every range configurable and validated.

Table I of the seed paper (section III.B), converted to metres and radians:

=========================================  ==============================  =====================
Table I                                    here                            default
=========================================  ==============================  =====================
objects per scene: 0 to 20 (text)          ``n_objects``                   (0, 20) inclusive
object largest dimension [4, 10] cm        ``largest_dim_m``               (0.04, 0.10)
object x, y position [-7.5, 7.5] cm        ``object_xy_m``                 (-0.075, 0.075)
object distance to ground 10k cm           ``drop_step_m``                 0.10 (object k at k x)
object Euler angles [0, pi]                ``euler_rad``                   (0, pi), R = Rz Ry Rx
camera x, y position 0                     ``camera_xy_m`` (a position)    (0, 0)
camera distance to ground [20, 40] cm      ``camera_height_m``             (0.20, 0.40)
camera rotation about z [-pi, pi]          ``camera_yaw_rad``              (-pi, pi)
camera rotation about x, y [-pi/18, pi/18] ``camera_tilt_rad``             (-pi/18, pi/18)
=========================================  ==============================  =====================

Beyond Table I: ``min_thickness_m`` (the paper's proposal V.a), the shape mix, the share of
objects drawn from a user library, and densities. Every random draw takes an
``np.random.Generator``; there is no global random state.

The small rotation helpers live here because scene sampling, physics and rendering share them.
"""

from __future__ import annotations

import math
import typing
from dataclasses import asdict, dataclass, field, fields
from functools import cache
from typing import Any

import numpy as np

from edge.errors import ConfigError
from edge.values import is_finite, is_number, show
from sim.shapes import (
    LONG_KINDS,
    PROCEDURAL_KINDS,
    THIN_KINDS,
    MeshLibrary,
    Shape,
    random_long,
    random_procedural,
    random_thin,
)

__all__ = [
    "SceneConfig",
    "ObjectSpec",
    "SceneSpec",
    "sample_scene",
    "config_from_dict",
    "check_range",
    "check_number",
    "check_value",
    "check_fields",
    "omit_neutral",
    "euler_to_quat",
    "quat_to_matrix",
    "camera_rotation",
]

_PI = math.pi
DEFAULT_WEIGHTS = {
    "box": 2.0,
    "cylinder": 1.5,
    "sphere": 1.0,
    "capsule": 1.0,
    "cone": 1.0,
    "torus": 0.7,
    "tube": 1.0,
    "superquadric": 1.5,
    "hull": 1.5,
    "union": 1.5,
}


# --------------------------------------------------------------------------- rotations


def euler_to_quat(a: float, b: float, c: float) -> np.ndarray:
    """(w, x, y, z) of R = Rz(c) Ry(b) Rx(a): Blender's default XYZ Euler, as the paper used."""
    ha, hb, hc = a / 2, b / 2, c / 2
    qx = np.array([math.cos(ha), math.sin(ha), 0.0, 0.0])
    qy = np.array([math.cos(hb), 0.0, math.sin(hb), 0.0])
    qz = np.array([math.cos(hc), 0.0, 0.0, math.sin(hc)])
    return _qmul(qz, _qmul(qy, qx))


def _qmul(p: np.ndarray, q: np.ndarray) -> np.ndarray:
    w1, x1, y1, z1 = p
    w2, x2, y2, z2 = q
    return np.array(
        [
            w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2,
            w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
            w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2,
            w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2,
        ]
    )


def quat_to_matrix(q: np.ndarray) -> np.ndarray:
    w, x, y, z = np.asarray(q, dtype=float) / np.linalg.norm(q)
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


def _rx(t: float) -> np.ndarray:
    c, s = math.cos(t), math.sin(t)
    return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])


def _ry(t: float) -> np.ndarray:
    c, s = math.cos(t), math.sin(t)
    return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])


def _rz(t: float) -> np.ndarray:
    c, s = math.cos(t), math.sin(t)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])


def camera_rotation(yaw: float, tilt_x: float, tilt_y: float) -> np.ndarray:
    """World-from-camera rotation of a camera looking straight down, then tilted and yawed.

    Camera axes follow the optical-frame convention (x right, y down, z forward); with no
    rotation, camera z is world -z and camera y is world -y.
    """
    down = np.diag([1.0, -1.0, -1.0])
    return _rz(yaw) @ _ry(tilt_y) @ _rx(tilt_x) @ down


# --------------------------------------------------------------------------- configuration helpers


def check_value(name: str, value: Any, kind: Any) -> None:
    """Refuse ``value`` unless it is what the type hint ``kind`` says, as JSON spells it.

    The one type rule for every simulator setting: a ``bool`` is a JSON boolean (``"no"`` is not
    false), an ``int`` a whole number, a ``float`` a finite number (NaN and Infinity, which
    Python's json accepts, are refused), a ``str`` a string, ``tuple[X, Y]`` a list of exactly
    those, ``tuple[X, ...]`` a list of X. A string is never a list (``"05"`` is not ``[0, 5]``).
    Other kinds (nested configs) must be instances of the class.

    Raises:
        ConfigError: naming the setting and the value.
    """
    origin = typing.get_origin(kind)
    if kind is bool:
        if not isinstance(value, (bool, np.bool_)):
            raise ConfigError(f"{name} must be true or false (a JSON boolean), got {show(value)}")
    elif kind is int:
        if not (is_number(value) and is_finite(value) and float(value) == int(value)):
            raise ConfigError(f"{name} must be a whole number, got {show(value)}")
    elif kind is float:
        if not (is_number(value) and is_finite(value)):
            raise ConfigError(f"{name} must be a finite number, got {show(value)}")
    elif kind is str:
        if not isinstance(value, str):
            raise ConfigError(f"{name} must be a string, got {show(value)}")
    elif origin is tuple:
        args = typing.get_args(kind)
        many = bool(args) and args[-1] is Ellipsis
        what = "strings" if args and args[0] is str else "numbers"
        want = f"a list of {what}" if many else f"a list of {len(args)} {what}"
        if not isinstance(value, (list, tuple)) or (not many and len(value) != len(args)):
            raise ConfigError(f"{name} must be {want}, got {show(value)}")
        kinds = [args[0]] * len(value) if many else list(args)
        for i, (v, k) in enumerate(zip(value, kinds)):
            check_value(f"{name}[{i}]", v, k)
    elif isinstance(kind, type) and not isinstance(value, kind):
        raise ConfigError(f"{name} must be a {kind.__name__}, got {show(value)}")


@cache
def _hints(cls: type) -> dict[str, Any]:
    return typing.get_type_hints(cls)


def check_fields(obj: Any, section: str) -> None:
    """`check_value` on every field of the dataclass ``obj`` (call it first in ``__post_init__``)."""
    hints = _hints(type(obj))
    for f in fields(obj):
        check_value(f"{section}.{f.name}", getattr(obj, f.name), hints[f.name])


def _check_kinds(name: str, kinds: tuple[str, ...], allowed: tuple[str, ...]) -> None:
    """A non-empty list of shape names from ``allowed``, or one ConfigError naming the bad ones."""
    bad = [k for k in kinds if k not in allowed]
    if not kinds or bad:
        raise ConfigError(f"{name}: unknown {bad or 'empty list'}; choose from {list(allowed)}")


def check_range(name: str, value: Any, lo_bound: float | None = None, hi_bound: float | None = None) -> tuple:
    """A (min, max) pair of finite numbers with min <= max, inside optional bounds."""
    if not (isinstance(value, (list, tuple)) and len(value) == 2 and all(is_number(v) for v in value)):
        raise ConfigError(f"{name} must be a [min, max] pair of numbers, got {show(value)}")
    if not (is_finite(value[0]) and is_finite(value[1])):
        raise ConfigError(f"{name} must be finite, got {show(list(value))}")
    lo, hi = float(value[0]), float(value[1])
    if lo > hi:
        raise ConfigError(f"{name}: min {lo} is above max {hi}; swap them")
    if lo_bound is not None and lo < lo_bound:
        raise ConfigError(f"{name}: min {lo} is below the allowed {lo_bound}")
    if hi_bound is not None and hi > hi_bound:
        raise ConfigError(f"{name}: max {hi} is above the allowed {hi_bound}")
    return lo, hi


def check_number(name: str, value: Any, lo: float | None = None, hi: float | None = None) -> None:
    """A finite number (not a bool, not a string) inside optional bounds."""
    if not is_number(value):
        raise ConfigError(f"{name} must be a number, got {show(value)}")
    if not is_finite(value) or (lo is not None and value < lo) or (hi is not None and value > hi):
        lim = f"[{'-inf' if lo is None else lo}, {'inf' if hi is None else hi}]"
        raise ConfigError(f"{name} = {show(value)} is outside {lim}")


def _short_keys(keys: list[str]) -> list[str]:
    """At most ten keys, each cut to 40 characters, for a one-line message."""
    return [k if len(k) <= 40 else k[:37] + "..." for k in keys[:10]] + (["..."] if len(keys) > 10 else [])


def config_from_dict(cls: type, d: dict[str, Any] | None, section: str) -> Any:
    """Build a frozen config dataclass from JSON-like data; unknown keys and bad values raise.

    Values are checked by type in the class's ``__post_init__`` (`check_fields`).
    """
    if d is None:
        return cls()
    if not isinstance(d, dict):
        raise ConfigError(f"config section '{section}' must be an object, got {type(d).__name__}")
    known = {f.name: f for f in fields(cls)}
    unknown = sorted(set(d) - set(known))
    if unknown:
        raise ConfigError(f"unknown {section} keys {_short_keys(unknown)}; valid keys: {sorted(known)}")
    kw = {k: (tuple(v) if isinstance(v, list) else v) for k, v in d.items()}
    try:
        return cls(**kw)
    except TypeError as exc:
        raise ConfigError(f"bad {section} config: {exc}") from None


def _to_dict(obj: Any) -> dict[str, Any]:
    return {k: (list(v) if isinstance(v, tuple) else v) for k, v in asdict(obj).items()}


def omit_neutral(d: dict[str, Any], neutral: dict[str, Any], digest_only: frozenset[str] = frozenset(),
                 for_digest: bool = False) -> dict[str, Any]:
    """``d`` without the keys added after data were made, where they hold their neutral value.

    Why: a setting added to a config must not change the digest (or the written config) of data
    simulated before it existed, as long as it is left at the value that reproduces those frames.

    Args:
        d: a config as JSON (`_to_dict`); modified in place and returned.
        neutral: key -> the value that means "as before the key existed" (tuples as lists).
        digest_only: keys always written, left out only of the digest (``for_digest``).
        for_digest: the dict feeds the config digest.
    """
    for k, v in neutral.items():
        if d[k] == v and (k not in digest_only or for_digest):
            del d[k]
    return d


# --------------------------------------------------------------------------- scene configuration


_MAX_CURVATURE = 1.0  # 1/m: at most 2.25 cm of sag 15 cm from the centre; physics assumes a flat table


@dataclass(frozen=True)
class SceneConfig:
    """What a scene may contain. Defaults: the paper's Table I (see the module docstring)."""

    n_objects: tuple[int, int] = (0, 20)
    largest_dim_m: tuple[float, float] = (0.04, 0.10)
    object_xy_m: tuple[float, float] = (-0.075, 0.075)
    drop_step_m: float = 0.10
    drop_clearance_m: float = 0.002  # gap under object k's lowest point at release
    euler_rad: tuple[float, float] = (0.0, _PI)
    camera_xy_m: tuple[float, float] = (0.0, 0.0)
    camera_height_m: tuple[float, float] = (0.20, 0.40)
    camera_yaw_rad: tuple[float, float] = (-_PI, _PI)
    camera_tilt_rad: tuple[float, float] = (-_PI / 18, _PI / 18)
    min_thickness_m: float = 0.01  # paper V.a: nothing so flat that it vanishes into the floor
    shapes: tuple[str, ...] = PROCEDURAL_KINDS
    shape_weights: tuple[float, ...] = field(default_factory=lambda: tuple(DEFAULT_WEIGHTS[k] for k in PROCEDURAL_KINDS))
    library_fraction: float = 1.0  # share of objects taken from --objects when a library is given
    density_kg_m3: tuple[float, float] = (200.0, 1200.0)
    # Scene families where a floor-plane fit fails (all off by default; see _FAMILY_DEFAULTS).
    thin_fraction: float = 0.0  # share of objects drawn flat (coins, plates, rings, flat tools)
    thin_thickness_m: tuple[float, float] = (0.003, 0.008)  # their thickness; ignores min_thickness_m
    thin_shapes: tuple[str, ...] = THIN_KINDS
    long_fraction: float = 0.0  # share of the other objects drawn long and narrow (handles, rods, sticks) ...
    long_length_m: tuple[float, float] = (0.12, 0.30)  # ... this long, beyond largest_dim_m ...
    long_diameter_m: tuple[float, float] = (0.01, 0.04)  # ... this thick, released lying, last
    long_shapes: tuple[str, ...] = LONG_KINDS
    table_edge_prob: float = 0.0  # per frame: the table ends in a straight edge ...
    table_edge_dist_m: tuple[float, float] = (0.09, 0.2)  # ... this far from the scene centre ...
    floor_drop_m: tuple[float, float] = (0.25, 0.8)  # ... with the room floor this far below
    support_curvature: tuple[float, float] = (0.0, 0.0)  # per frame k of a table z = k (x^2 + y^2), 1/m
    tray_prob: float = 0.0  # per frame: objects are dropped into a tray whose walls are background
    tray_inner_m: tuple[float, float] = (0.14, 0.24)  # inner side lengths (each side drawn alone)
    tray_wall_height_m: tuple[float, float] = (0.02, 0.06)
    tray_wall_thickness_m: tuple[float, float] = (0.003, 0.01)
    # Per scene: no objects at all, whatever n_objects says. Table I's uniform 0-20 leaves ~5 %
    # of scenes empty, and an empty frame scores 0 with a single false object pixel, so a model
    # that rarely sees bare trays and table edges paints their rims (BENCHMARKS.md "candidate C6").
    empty_prob: float = 0.0
    # Camera poses rendered per settled scene (sim.views): frame i shows scene i // V from view i % V.
    # 4: physics paid once per 4 frames (1.7-1.9x the frames/s of one view with 2 workers here) at
    # no held-out accuracy cost (BENCHMARKS.md "Views per scene"); 1 is the paper's one pose a scene.
    views_per_scene: int = 4

    def __post_init__(self) -> None:
        check_fields(self, "scene")
        n = check_range("scene.n_objects", self.n_objects, 0, 200)
        if any(float(v) != int(v) for v in n):
            raise ConfigError(f"scene.n_objects must be whole numbers, got {list(self.n_objects)}")
        check_range("scene.largest_dim_m", self.largest_dim_m, 1e-3, 2.0)
        check_range("scene.object_xy_m", self.object_xy_m)
        check_number("scene.drop_step_m", self.drop_step_m, 0.0, 5.0)
        check_number("scene.drop_clearance_m", self.drop_clearance_m, 0.0, 1.0)
        check_range("scene.euler_rad", self.euler_rad)
        try:
            cx, cy = (float(v) for v in self.camera_xy_m)
        except (TypeError, ValueError):
            raise ConfigError(f"scene.camera_xy_m must be an [x, y] position, got {self.camera_xy_m!r}") from None
        if not (math.isfinite(cx) and math.isfinite(cy)):
            raise ConfigError(f"scene.camera_xy_m must be finite, got {self.camera_xy_m!r}")
        check_range("scene.camera_height_m", self.camera_height_m, 0.05, 5.0)
        check_range("scene.camera_yaw_rad", self.camera_yaw_rad)
        check_range("scene.camera_tilt_rad", self.camera_tilt_rad, -_PI / 3, _PI / 3)
        check_number("scene.min_thickness_m", self.min_thickness_m, 0.0)
        if self.min_thickness_m > self.largest_dim_m[0]:
            raise ConfigError(
                f"scene.min_thickness_m {self.min_thickness_m} is above the smallest largest_dim_m "
                f"{self.largest_dim_m[0]}; lower it"
            )
        if not self.shapes:
            raise ConfigError(f"scene.shapes is empty; choose from {list(PROCEDURAL_KINDS)}")
        bad = [s for s in self.shapes if s not in PROCEDURAL_KINDS]
        if bad:
            raise ConfigError(f"scene.shapes: unknown {bad}; choose from {list(PROCEDURAL_KINDS)}")
        if len(self.shape_weights) != len(self.shapes):
            if self.shape_weights == tuple(DEFAULT_WEIGHTS[k] for k in PROCEDURAL_KINDS):
                object.__setattr__(self, "shape_weights", tuple(DEFAULT_WEIGHTS[k] for k in self.shapes))
            else:
                raise ConfigError(
                    f"scene.shape_weights has {len(self.shape_weights)} entries for {len(self.shapes)} shapes"
                )
        w = np.asarray(self.shape_weights, float)
        if not np.all(np.isfinite(w)) or np.any(w < 0) or w.sum() <= 0:
            raise ConfigError(f"scene.shape_weights must be non-negative with a positive sum, got {list(self.shape_weights)}")
        check_number("scene.library_fraction", self.library_fraction, 0.0, 1.0)
        check_range("scene.density_kg_m3", self.density_kg_m3, 1.0, 1e5)
        v = self.views_per_scene
        if isinstance(v, bool) or not isinstance(v, int) or not 1 <= v <= 1000:
            raise ConfigError(f"scene.views_per_scene must be a whole number in [1, 1000], got {v!r}")
        self._check_families()

    def _check_families(self) -> None:
        """Validate the plane-fit-failure families (thin objects, table edge, curvature, trays)."""
        check_number("scene.thin_fraction", self.thin_fraction, 0.0, 1.0)
        check_range("scene.thin_thickness_m", self.thin_thickness_m, 1e-4, 0.05)
        if self.thin_thickness_m[1] > self.largest_dim_m[0]:
            raise ConfigError(
                f"scene.thin_thickness_m max {self.thin_thickness_m[1]} is above the smallest largest_dim_m "
                f"{self.largest_dim_m[0]}; lower it"
            )
        _check_kinds("scene.thin_shapes", self.thin_shapes, THIN_KINDS)
        check_number("scene.long_fraction", self.long_fraction, 0.0, 1.0)
        check_range("scene.long_length_m", self.long_length_m, 0.005, 2.0)
        check_range("scene.long_diameter_m", self.long_diameter_m, 0.001, 0.5)
        _check_kinds("scene.long_shapes", self.long_shapes, LONG_KINDS)
        check_number("scene.table_edge_prob", self.table_edge_prob, 0.0, 1.0)
        check_range("scene.table_edge_dist_m", self.table_edge_dist_m, 0.0, 10.0)
        check_range("scene.floor_drop_m", self.floor_drop_m, 0.01, 10.0)
        check_range("scene.support_curvature", self.support_curvature, -_MAX_CURVATURE, _MAX_CURVATURE)
        check_number("scene.tray_prob", self.tray_prob, 0.0, 1.0)
        check_range("scene.tray_inner_m", self.tray_inner_m, 0.02, 2.0)
        check_range("scene.tray_wall_height_m", self.tray_wall_height_m, 0.001, 0.5)
        check_range("scene.tray_wall_thickness_m", self.tray_wall_thickness_m, 0.0005, 0.1)
        check_number("scene.empty_prob", self.empty_prob, 0.0, 1.0)
        reach = max(abs(float(v)) for v in self.object_xy_m)
        if self.table_edge_prob > 0 and self.table_edge_dist_m[0] <= reach:
            raise ConfigError(
                f"scene.table_edge_dist_m min {self.table_edge_dist_m[0]} must exceed the object_xy_m reach "
                f"{reach}; raise it so objects are dropped onto the table"
            )

    def to_dict(self, for_digest: bool = False) -> dict[str, Any]:
        """Family keys at their neutral values are left out, so old configs keep their digest.

        ``views_per_scene`` defaults to 4 but its neutral value (what every config before it
        meant) is 1: it is always written, so a one-view config reads back as one view, and
        left out of the digest only at 1 (``for_digest``), so one-view data keep their digest.
        """
        return omit_neutral(_to_dict(self), _FAMILY_DEFAULTS, frozenset({"views_per_scene"}), for_digest)

    @classmethod
    def from_dict(cls, d: dict[str, Any] | None) -> SceneConfig:
        return config_from_dict(cls, d, "scene")


_FAMILY_DEFAULTS = {
    k: (list(v) if isinstance(v, tuple) else v)
    for k, v in {
        "thin_fraction": 0.0,
        "thin_thickness_m": (0.003, 0.008),
        "thin_shapes": THIN_KINDS,
        "long_fraction": 0.0,
        "long_length_m": (0.12, 0.30),
        "long_diameter_m": (0.01, 0.04),
        "long_shapes": LONG_KINDS,
        "table_edge_prob": 0.0,
        "table_edge_dist_m": (0.09, 0.2),
        "floor_drop_m": (0.25, 0.8),
        "support_curvature": (0.0, 0.0),
        "tray_prob": 0.0,
        "tray_inner_m": (0.14, 0.24),
        "tray_wall_height_m": (0.02, 0.06),
        "tray_wall_thickness_m": (0.003, 0.01),
        "empty_prob": 0.0,
        "views_per_scene": 1,
    }.items()
}


# --------------------------------------------------------------------------- sampled scenes


@dataclass(eq=False)
class ObjectSpec:
    """One object at release: its shape, where it starts and how heavy it is."""

    shape: Shape
    pos: np.ndarray  # (3,) release position of the body frame, metres
    quat: np.ndarray  # (4,) w x y z
    density: float
    euler: tuple[float, float, float]


@dataclass
class TableEdge:
    """A straight table edge: the table is {p : p . (cos a, sin a) <= dist_m}; beyond it, the
    room floor lies drop_m lower. ``drawn_dist_m`` is the drawn distance; ``dist_m`` may be
    pushed out after the drop so that no resting object centre (or tray) hangs in the air."""

    angle_rad: float
    dist_m: float
    drop_m: float
    drawn_dist_m: float

    @property
    def normal(self) -> tuple[float, float]:
        return (math.cos(self.angle_rad), math.sin(self.angle_rad))

    def to_params(self) -> dict[str, Any]:
        return {
            "angle_rad": round(self.angle_rad, 6),
            "dist_m": round(self.dist_m, 6),
            "drawn_dist_m": round(self.drawn_dist_m, 6),
            "floor_drop_m": round(self.drop_m, 6),
        }


@dataclass
class Tray:
    """An open tray centred on the scene, yawed by ``yaw_rad``; its walls are background."""

    inner_m: tuple[float, float]  # inner side lengths along the tray's x and y
    wall_height_m: float
    wall_thickness_m: float
    yaw_rad: float

    def walls(self) -> list[tuple[np.ndarray, np.ndarray, np.ndarray]]:
        """Four static boxes (half sides, centre, world rotation); the x walls cover the corners."""
        ax, ay = self.inner_m[0] / 2, self.inner_m[1] / 2
        t, h = self.wall_thickness_m, self.wall_height_m
        rot = _rz(self.yaw_rad)
        boxes = [
            ((t / 2, ay + t, h / 2), (s * (ax + t / 2), 0.0, h / 2)) for s in (1, -1)
        ] + [((ax, t / 2, h / 2), (0.0, s * (ay + t / 2), h / 2)) for s in (1, -1)]
        return [(np.array(half), rot @ np.array(c), rot) for half, c in boxes]

    def corners(self) -> np.ndarray:
        """Outer corners (4, 2) in world x, y."""
        ox, oy = self.inner_m[0] / 2 + self.wall_thickness_m, self.inner_m[1] / 2 + self.wall_thickness_m
        c = np.array([[ox, oy], [-ox, oy], [-ox, -oy], [ox, -oy]])
        return c @ _rz(self.yaw_rad)[:2, :2].T

    def keep_inside(self, obj: ObjectSpec) -> None:
        """Move an object's release x, y so that it falls into the tray (centred if too big)."""
        rot = _rz(self.yaw_rad)
        verts = obj.shape.vertices.astype(np.float64) @ quat_to_matrix(obj.quat).T
        local = (verts @ rot)[:, :2]  # vertex offsets in the tray frame
        p = rot.T @ obj.pos
        for i in range(2):
            lo = -self.inner_m[i] / 2 - local[:, i].min()
            hi = self.inner_m[i] / 2 - local[:, i].max()
            p[i] = float(np.clip(p[i], lo, hi)) if lo <= hi else (lo + hi) / 2
        obj.pos = rot @ p

    def to_params(self) -> dict[str, Any]:
        return {
            "inner_m": [round(v, 6) for v in self.inner_m],
            "wall_height_m": round(self.wall_height_m, 6),
            "wall_thickness_m": round(self.wall_thickness_m, 6),
            "yaw_rad": round(self.yaw_rad, 6),
        }


@dataclass
class SupportSpec:
    """What the objects stand on when a support family is enabled (None fields: not drawn)."""

    table_edge: TableEdge | None = None
    curvature: float = 0.0  # table top z = k (x^2 + y^2); 0 = flat
    tray: Tray | None = None

    def height(self, xy: np.ndarray) -> np.ndarray:
        """Height of the table top at world (x, y) points (N, 2)."""
        return self.curvature * np.sum(np.asarray(xy, np.float64) ** 2, axis=-1)

    def to_params(self) -> dict[str, Any]:
        return {
            "table_edge": None if self.table_edge is None else self.table_edge.to_params(),
            "curvature_per_m": round(self.curvature, 6),
            "tray": None if self.tray is None else self.tray.to_params(),
        }


_EDGE_MARGIN_M = 0.01  # resting object centres stay at least this far inside the table edge


@dataclass(eq=False)
class SceneSpec:
    camera_height: float
    camera_xy: tuple[float, float]
    yaw: float
    tilt_x: float
    tilt_y: float
    objects: list[ObjectSpec]
    support: SupportSpec | None = None  # None: no support family enabled, the plane z = 0

    @property
    def camera_position(self) -> np.ndarray:
        return np.array([self.camera_xy[0], self.camera_xy[1], self.camera_height])

    @property
    def camera_rotation(self) -> np.ndarray:
        return camera_rotation(self.yaw, self.tilt_x, self.tilt_y)

    def rest_on_support(self, pos: np.ndarray) -> np.ndarray:
        """Resting positions on the real support (physics drops onto the plane z = 0).

        Pushes a table edge out past every resting object centre, so nothing floats beyond it.
        """
        if self.support is None:
            return pos
        edge = self.support.table_edge
        if edge is not None:
            xy = pos[:, :2] if self.support.tray is None else np.vstack([pos[:, :2], self.support.tray.corners()])
            if len(xy):
                edge.dist_m = max(edge.dist_m, float((xy @ np.asarray(edge.normal)).max()) + _EDGE_MARGIN_M)
        if self.support.curvature != 0.0 and len(pos):
            pos = pos.copy()
            pos[:, 2] += self.support.height(pos[:, :2])  # dropped on the flat plane: lift onto the curve
        return pos

    def render_support(self) -> Any:
        """The `sim.render.Support` to cast against, or None for the plain floor plane."""
        from sim.render import Support

        sup = self.support
        if sup is None or (sup.table_edge is None and sup.curvature == 0.0):
            return None
        e = sup.table_edge
        if e is None:
            return Support(curvature=sup.curvature)
        return Support(curvature=sup.curvature, edge_normal=e.normal, edge_dist=e.dist_m, drop=e.drop_m)

    def background_meshes(self) -> list[tuple[np.ndarray, np.ndarray]]:
        """World-frame meshes that are background (label 0) but not the analytic support."""
        from sim.shapes import box_mesh

        out = []
        for half, centre, rot in self.static_boxes():
            v, t = box_mesh(half)
            out.append(((v.astype(np.float64) @ rot.T + centre).astype(np.float32), t))
        return out

    def static_boxes(self) -> list[tuple[np.ndarray, np.ndarray, np.ndarray]]:
        """Fixed background boxes (half sides, centre, rotation) that objects collide with."""
        if self.support is None or self.support.tray is None:
            return []
        return self.support.tray.walls()

    def to_params(self) -> dict[str, Any]:
        """JSON-ready description (release poses; physics adds the resting poses)."""
        extra = {} if self.support is None else {"support": self.support.to_params()}
        return {
            **extra,
            "camera": {
                "height_m": round(self.camera_height, 6),
                "xy_m": [round(v, 6) for v in self.camera_xy],
                "yaw_rad": round(self.yaw, 6),
                "tilt_x_rad": round(self.tilt_x, 6),
                "tilt_y_rad": round(self.tilt_y, 6),
            },
            "objects": [
                {
                    "shape": o.shape.kind,
                    **o.shape.params,
                    "euler_rad": [round(v, 6) for v in o.euler],
                    "release_pos_m": o.pos.round(6).tolist(),
                    "density_kg_m3": round(o.density, 3),
                }
                for o in self.objects
            ],
        }


def _u(rng: np.random.Generator, r: tuple[float, float]) -> float:
    return float(rng.uniform(r[0], r[1])) if r[1] > r[0] else float(r[0])


_THIN_TILT_RAD = 0.25  # thin objects are released nearly flat so they settle flat
_LONG_TILT_RAD = 0.3  # long objects are released within this of lying down, at any yaw


def _release(rng: np.random.Generator, cfg: SceneConfig, shape: Shape, euler: tuple[float, float, float], k: int) -> ObjectSpec:
    """Object k released with its lowest point drop_clearance above slot k * drop_step (Table I)."""
    q = euler_to_quat(*euler)
    lowest = float((shape.vertices.astype(np.float64) @ quat_to_matrix(q)[2]).min())
    z = k * cfg.drop_step_m + cfg.drop_clearance_m - lowest
    pos = np.array([_u(rng, cfg.object_xy_m), _u(rng, cfg.object_xy_m), z])
    return ObjectSpec(shape, pos, q, _u(rng, cfg.density_kg_m3), euler)


def _thin_object(rng: np.random.Generator, cfg: SceneConfig, k: int) -> ObjectSpec:
    """A flat object released nearly level in slot k (thin objects take the lowest slots)."""
    shape = random_thin(rng, _u(rng, cfg.largest_dim_m), _u(rng, cfg.thin_thickness_m), cfg.thin_shapes)
    tilt = rng.uniform(-_THIN_TILT_RAD, _THIN_TILT_RAD, size=2)
    return _release(rng, cfg, shape, (float(tilt[0]), float(tilt[1]), float(rng.uniform(-_PI, _PI))), k)


def _long_object(rng: np.random.Generator, cfg: SceneConfig, k: int) -> ObjectSpec:
    """A long narrow object released lying in slot k (long objects take the highest slots, so
    they fall onto the others and often lean across them, like a brush on a cluttered table)."""
    shape = random_long(rng, _u(rng, cfg.long_length_m), _u(rng, cfg.long_diameter_m), cfg.long_shapes)
    tilt = rng.uniform(-_LONG_TILT_RAD, _LONG_TILT_RAD, size=2)
    return _release(rng, cfg, shape, (float(_PI / 2 + tilt[0]), float(tilt[1]), float(rng.uniform(-_PI, _PI))), k)


def sample_scene(rng: np.random.Generator, cfg: SceneConfig, library: MeshLibrary | None = None) -> SceneSpec:
    """Draw one scene; objects are stacked in release order k at k * drop_step above the floor.

    Family draws happen only when their family is enabled, so the default configuration keeps
    its random stream (and its frames) unchanged.
    """
    n = int(rng.integers(int(cfg.n_objects[0]), int(cfg.n_objects[1]) + 1))
    if cfg.empty_prob > 0 and rng.random() < cfg.empty_prob:
        n = 0
    n_thin = int(rng.binomial(n, cfg.thin_fraction)) if cfg.thin_fraction > 0 else 0
    n_long = int(rng.binomial(n - n_thin, cfg.long_fraction)) if cfg.long_fraction > 0 else 0
    objects: list[ObjectSpec] = []
    for k in range(n):
        if k < n_thin:
            objects.append(_thin_object(rng, cfg, k))
            continue
        if k >= n - n_long:
            objects.append(_long_object(rng, cfg, k))
            continue
        largest = _u(rng, cfg.largest_dim_m)
        if library is not None and len(library) and rng.random() < cfg.library_fraction:
            shape = library.shape(int(rng.integers(len(library))), largest, cfg.min_thickness_m)
        else:
            shape = random_procedural(rng, largest, cfg.min_thickness_m, cfg.shapes, cfg.shape_weights)
        euler = (_u(rng, cfg.euler_rad), _u(rng, cfg.euler_rad), _u(rng, cfg.euler_rad))
        objects.append(_release(rng, cfg, shape, euler, k))
    camera = {
        "camera_height": _u(rng, cfg.camera_height_m),
        "camera_xy": (float(cfg.camera_xy_m[0]), float(cfg.camera_xy_m[1])),
        "yaw": _u(rng, cfg.camera_yaw_rad),
        "tilt_x": _u(rng, cfg.camera_tilt_rad),
        "tilt_y": _u(rng, cfg.camera_tilt_rad),
    }
    return SceneSpec(**camera, objects=objects, support=_sample_support(rng, cfg, objects))


def _support_enabled(cfg: SceneConfig) -> bool:
    return cfg.table_edge_prob > 0 or cfg.tray_prob > 0 or any(float(k) != 0.0 for k in cfg.support_curvature)


def _sample_support(rng: np.random.Generator, cfg: SceneConfig, objects: list[ObjectSpec]) -> SupportSpec | None:
    """Per-frame support draws, after every Table I draw (the default stream is untouched).

    A tray moves the objects' release points inside it and rules out curvature (its walls
    stand on a flat bottom).
    """
    if not _support_enabled(cfg):
        return None
    sup = SupportSpec()
    if cfg.table_edge_prob > 0 and rng.random() < cfg.table_edge_prob:
        dist = _u(rng, cfg.table_edge_dist_m)
        sup.table_edge = TableEdge(float(rng.uniform(-_PI, _PI)), dist, _u(rng, cfg.floor_drop_m), dist)
    if cfg.tray_prob > 0 and rng.random() < cfg.tray_prob:
        inner = (_u(rng, cfg.tray_inner_m), _u(rng, cfg.tray_inner_m))
        sup.tray = Tray(inner, _u(rng, cfg.tray_wall_height_m), _u(rng, cfg.tray_wall_thickness_m), float(rng.uniform(-_PI, _PI)))
        for obj in objects:
            sup.tray.keep_inside(obj)
    if sup.tray is None and any(float(k) != 0.0 for k in cfg.support_curvature):
        sup.curvature = _u(rng, cfg.support_curvature)
    return sup
