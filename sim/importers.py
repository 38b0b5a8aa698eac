"""Bring depth frames made by other tools into the depthseg MCAP layout (`edge.io`).

Two sources, so training, evaluation and replay read one format:

- **BlenSor scans** (the seed paper's dataset, ``scan_*.npy``): float64 ``(2, 38304)``; row 0 is
  the noisy *radial* range in metres, row 1 the object id per pixel; ``row.reshape(224, 171).T``
  is the 171 x 224 (H x W) image. We publish Z (ROS convention): ``Z = r / sqrt(1 + xn^2 + yn^2)``.
  BlenSor's ToF camera (``tof.py``) casts the ray of pixel x through ``(x - W/2) * pixel_width``,
  so its principal point is ``(W/2, H/2) = (112, 85.5)``, half a pixel off the symmetric
  ``((W-1)/2, (H-1)/2)`` of `edge.meta.fov_intrinsics`. The data agree: fitting one plane per
  scan to the background pixels of all ten shared scans (3-D points from Z), the residual sum
  of squares is smallest at cx = 112.0 (delta-chi2 +17 at 111.5, +60 at 111, i.e. the image is
  not mirrored) and at cy ~ 85.25 (85.0 and 85.5 within delta-chi2 2 of it, the data cannot tell
  them apart); fx, fy from the 62 x 45 deg lens angles are confirmed (2 % off costs
  delta-chi2 > 1000). The background plane then has 3.6 mm RMS residual, the BlenSor
  noise (sigma 4 mm radial); the raw radial image is curved by up to ~4 cm.
  The background id is the ground's (``"grou"`` as four ASCII bytes, 1970238055 in the paper's
  files); see `detect_background_id`. Label = id != background.
- **royaleviewer PLY captures** (real pico flexx): ASCII PLY, one vertex per pixel, row-major
  171 x 224, x y z in metres (camera frame, undistorted), grey r = g = b, invalid = (0, 0, 0).
  Depth = z. There is no CameraInfo in a PLY, so pinhole intrinsics are fitted to the points
  (``u = fx * x / z + cx`` by least squares over valid pixels). The pixel grid is the lens-
  distorted one while the points are undistorted, so the fit leaves ~1.5-2 px RMS; the residual
  is written to the scene JSON. The grey amplitude goes to ``/pico_flexx/image_mono8``.

Timestamps are synthetic: frame i at ``SIM_EPOCH_NS + i * 100 ms`` (sources carry no time).
"""

from __future__ import annotations

import argparse
import re
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from edge.errors import DataError, first_line
from edge.io import SIM_EPOCH_NS, FrameWriter
from edge.io.paths import check_input_file, check_outputs
from edge.meta import fov_intrinsics

__all__ = [
    "BLENSOR_WIDTH",
    "BLENSOR_HEIGHT",
    "TOPIC_MONO8",
    "FRAME_PERIOD_NS",
    "BlensorScan",
    "PlyCapture",
    "ImportSummary",
    "blensor_intrinsics",
    "read_blensor_scan",
    "detect_background_id",
    "radial_to_z",
    "blensor_frame",
    "read_ply",
    "fit_intrinsics",
    "find_inputs",
    "import_blensor",
    "import_ply",
    "import_main",
]

BLENSOR_WIDTH = 224
BLENSOR_HEIGHT = 171
TOPIC_MONO8 = "/pico_flexx/image_mono8"  # pico_flexx_driver's name for the 8-bit amplitude image
FRAME_PERIOD_NS = 100_000_000
_MIN_FIT_PIXELS = 100


def blensor_intrinsics(
    width: int = BLENSOR_WIDTH, height: int = BLENSOR_HEIGHT, hfov_deg: float = 62.0, vfov_deg: float = 45.0
) -> tuple[float, float, float, float]:
    """(fx, fy, cx, cy) of BlenSor's ToF pinhole: focal lengths from the lens angles, principal
    point at (W/2, H/2) as BlenSor's ray setup puts it (checked against the data, module doc)."""
    fx, fy, _, _ = fov_intrinsics(width, height, hfov_deg, vfov_deg)
    return fx, fy, width / 2.0, height / 2.0


# --------------------------------------------------------------------------------------- BlenSor


@dataclass(frozen=True)
class BlensorScan:
    """One BlenSor scan as images: radial range (m) and object id, both H x W float64."""

    path: Path
    radial: np.ndarray
    ids: np.ndarray


def read_blensor_scan(path: str | Path, width: int = BLENSOR_WIDTH, height: int = BLENSOR_HEIGHT) -> BlensorScan:
    """Load one ``scan_*.npy`` and check its shape before trusting it."""
    p = Path(path)
    if not p.exists():
        raise DataError(f"{p}: no such file")
    if p.is_dir():
        raise DataError(f"{p}: is a directory, expected a BlenSor scan_*.npy file")
    try:  # mapped, so the shape is checked before a damaged header can ask for any memory
        a = np.load(p, mmap_mode="r", allow_pickle=False)
    except (ValueError, OSError, EOFError) as exc:
        first = first_line(exc)
        if "mmap length" in first:
            first = "the file is shorter than its header declares: truncated or damaged"
        raise DataError(f"{p}: not a readable .npy array ({first[:120]})") from None
    if not isinstance(a, np.ndarray):
        raise DataError(f"{p}: not a .npy array (an .npz archive?); give BlenSor scan_*.npy files")
    n = width * height
    if a.shape != (2, n):
        raise DataError(
            f"{p}: BlenSor scan has shape {tuple(a.shape)}; expected (2, {n}) "
            f"(row 0 radial range, row 1 object id, {width} x {height} pixels)"
        )
    if not np.issubdtype(a.dtype, np.number):
        raise DataError(f"{p}: BlenSor scan has dtype {a.dtype}; expected numbers")
    a = np.array(a, dtype=np.float64)  # read from the map into memory
    return BlensorScan(p, a[0].reshape(width, height).T.copy(), a[1].reshape(width, height).T.copy())


def detect_background_id(scans: Sequence[BlensorScan]) -> float:
    """The ground's object id.

    A scan holding a single id is background only (scan_0 in the paper's data): its id wins,
    and several such scans must agree. Otherwise the ground is what the camera sees around the
    frame border (it looks down at a floor with objects in the middle): the id covering most
    border pixels over all scans.
    """
    if not scans:
        raise DataError("no BlenSor scans given; pass scan_*.npy files or their directory")
    singles = {float(np.unique(s.ids)[0]) for s in scans if np.unique(s.ids).size == 1}
    if len(singles) > 1:
        raise DataError(
            f"scans with a single object id disagree on the background id ({sorted(singles)}); "
            "pass `background_id`"
        )
    if singles:
        return singles.pop()
    border = np.concatenate(
        [np.concatenate([s.ids[0], s.ids[-1], s.ids[1:-1, 0], s.ids[1:-1, -1]]) for s in scans]
    )
    vals, counts = np.unique(border, return_counts=True)
    return float(vals[int(np.argmax(counts))])


def _normalised_ray_norm(
    shape: tuple[int, int], intrinsics: tuple[float, float, float, float]
) -> np.ndarray:
    fx, fy, cx, cy = intrinsics
    h, w = shape
    xn = (np.arange(w, dtype=np.float64) - cx) / fx
    yn = (np.arange(h, dtype=np.float64) - cy) / fy
    return np.sqrt(1.0 + xn[None, :] ** 2 + yn[:, None] ** 2)


def radial_to_z(radial: np.ndarray, intrinsics: tuple[float, float, float, float]) -> np.ndarray:
    """Z (along the optical axis) from range along each pixel's ray; invalid (<= 0, NaN, inf) -> 0."""
    r = np.asarray(radial, dtype=np.float64)
    with np.errstate(invalid="ignore"):
        ok = np.isfinite(r) & (r > 0)
    z = np.where(ok, r, 0.0) / _normalised_ray_norm(r.shape, intrinsics)
    return z.astype(np.float32)


def blensor_frame(
    scan: BlensorScan, background_id: float, intrinsics: tuple[float, float, float, float] | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """(Z depth float32 with 0 = invalid, label uint8 with 1 = object) of one scan."""
    k = intrinsics or blensor_intrinsics(scan.radial.shape[1], scan.radial.shape[0])
    depth = radial_to_z(scan.radial, k)
    label = (scan.ids != background_id).astype(np.uint8)
    return depth, label


# ------------------------------------------------------------------------------------------- PLY


@dataclass(frozen=True)
class PlyCapture:
    """One royaleviewer capture as images: points (H x W x 3, m) and grey (H x W uint8)."""

    path: Path
    points: np.ndarray
    grey: np.ndarray | None

    @property
    def valid(self) -> np.ndarray:
        z = self.points[..., 2]
        with np.errstate(invalid="ignore"):
            return np.isfinite(self.points).all(axis=-1) & (z > 0)

    @property
    def depth(self) -> np.ndarray:
        """Z in metres, float32, 0 where the camera gave no return."""
        return np.where(self.valid, self.points[..., 2], 0.0).astype(np.float32)


_PLY_SCALARS = {
    "char", "uchar", "short", "ushort", "int", "uint", "float", "double",
    "int8", "uint8", "int16", "uint16", "int32", "uint32", "float32", "float64",
}  # fmt: skip


_MAX_PLY_HEADER = 1 << 20  # bytes: a royaleviewer header is ~250; parsing a huge one would take minutes


def _parse_ply_header(fh, path: Path) -> tuple[list[tuple[str, int, list[str], bool]], int]:
    """[(element, count, property names, has list property)], number of header lines."""
    first = fh.readline(64)
    if first.strip() != b"ply":
        raise DataError(f"{path}: not a PLY file (first line is not 'ply')")
    elements: list[tuple[str, int, list[str], bool]] = []
    fmt = None
    n_lines = 1
    while True:
        raw = fh.readline(_MAX_PLY_HEADER + 1 - fh.tell())
        n_lines += 1
        if fh.tell() > _MAX_PLY_HEADER:
            raise DataError(f"{path}: PLY header is longer than {_MAX_PLY_HEADER} bytes (no 'end_header'); not a capture")
        if not raw:
            raise DataError(f"{path}: PLY header has no 'end_header' line (truncated file?)")
        line = raw.decode("ascii", errors="replace").strip()
        shown = line if len(line) <= 60 else line[:57] + "..."
        if line == "end_header":
            break
        parts = line.split()
        if not parts or parts[0] in ("comment", "obj_info"):
            continue
        if parts[0] == "format":
            fmt = parts[1] if len(parts) > 1 else ""
            if fmt != "ascii":
                raise DataError(
                    f"{path}: PLY format '{fmt[:20]}': only ASCII PLY supported; export it from royaleviewer as ASCII PLY"
                )
        elif parts[0] == "element" and len(parts) == 3:
            try:
                count = int(parts[2])
            except ValueError:
                raise DataError(f"{path}: bad PLY header line '{shown}'") from None
            if count < 0:
                raise DataError(f"{path}: PLY element '{parts[1][:20]}' has a negative count {count}")
            elements.append((parts[1], count, [], False))
        elif parts[0] == "property" and elements:
            name, count, props, has_list = elements[-1]
            if len(parts) >= 2 and parts[1] == "list":
                has_list = True
            elif len(parts) != 3 or parts[1] not in _PLY_SCALARS:
                raise DataError(f"{path}: bad PLY header line '{shown}'")
            props.append(parts[-1])
            elements[-1] = (name, count, props, has_list)
        else:
            raise DataError(f"{path}: bad PLY header line '{shown}'")
    if fmt is None:
        raise DataError(f"{path}: PLY header has no 'format' line")
    return elements, n_lines


def _skip_lines(fh, count: int, chunk: int = 1 << 20) -> int:
    """Move ``fh`` past ``count`` lines by counting newlines in blocks; returns the lines skipped."""
    done = 0
    while done < count:
        pos = fh.tell()
        block = fh.read(chunk)
        if not block:
            break
        ends = np.flatnonzero(np.frombuffer(block, dtype=np.uint8) == 10)
        if done + len(ends) >= count:
            fh.seek(pos + int(ends[count - done - 1]) + 1)
            return count
        done += len(ends)
    return done


def _check_rows_fit(path: Path, name: str, count: int, n_props: int, left: int) -> None:
    """Refuse an element whose rows could not fit in the ``left`` bytes of the file.

    Each ASCII row holds at least one character and a separator per property (an empty row is
    one newline): a header claiming more rows than that is damaged, and skipping them one by
    one would spin for as long as the count says.
    """
    min_bytes = max(2 * n_props, 1)
    if count > left // min_bytes:
        raise DataError(
            f"{path}: PLY element '{name[:20]}' declares {count} rows of {n_props} values, more than the {left} "
            "bytes left in the file can hold (truncated file or damaged header)"
        )


def read_ply(path: str | Path, width: int = BLENSOR_WIDTH, height: int = BLENSOR_HEIGHT) -> PlyCapture:
    """Parse a royaleviewer ASCII PLY (one vertex per pixel, row-major) into images.

    Every vertex row must hold exactly one value per property of the header; a ragged row is
    an error naming its line, never values shifted into the next pixel.
    """
    p = check_input_file(path, "inputs")
    if not (isinstance(width, int) and isinstance(height, int) and width > 0 and height > 0):
        raise DataError(f"`width`/`height` must be positive whole numbers, got {width!r} x {height!r}")
    size = p.stat().st_size
    with open(p, "rb") as fh:
        elements, line_no = _parse_ply_header(fh, p)  # line_no: the last line read
        vertex = None
        for name, count, props, has_list in elements:
            if name == "vertex":
                vertex = (count, props, has_list)
                break
            if has_list:
                raise DataError(f"{p}: PLY element '{name[:20]}' before the vertices holds lists; cannot read it")
            _check_rows_fit(p, name, count, len(props), size - fh.tell())
            if _skip_lines(fh, count) < count:
                raise DataError(f"{p}: PLY is truncated in element '{name[:20]}' ({count} rows declared)")
            line_no += count
        if vertex is None:
            raise DataError(f"{p}: PLY has no 'vertex' element")
        count, props, has_list = vertex
        n = width * height
        if count != n:
            raise DataError(
                f"{p}: PLY has {count} vertices; expected {n} ({width} x {height}, one per pixel, as "
                "royaleviewer exports a frame); pass `width`/`height` for another camera"
            )
        if has_list:
            raise DataError(f"{p}: PLY vertices hold a list property; a royaleviewer capture has none")
        missing = [c for c in ("x", "y", "z") if c not in props]
        if missing:
            raise DataError(f"{p}: PLY vertices lack properties {missing}; have {props[:20]}")
        _check_rows_fit(p, "vertex", count, len(props), size - fh.tell())
        table = np.empty((count, len(props)), dtype=np.float64)
        max_row = 64 + 64 * len(props)  # bytes: a row of numbers is far shorter; bounds split()'s memory
        for i in range(count):
            raw = fh.readline(max_row)
            line_no += 1
            if not raw:
                raise DataError(f"{p}: PLY is truncated: {i} of {count} vertex lines")
            if len(raw) >= max_row and not raw.endswith(b"\n"):
                raise DataError(f"{p}: line {line_no} (vertex {i}) is longer than {max_row} bytes; not a row of numbers")
            values = raw.split()
            if len(values) != len(props):
                raise DataError(
                    f"{p}: line {line_no} (vertex {i}) holds {len(values)} values; the header declares "
                    f"{len(props)} properties ({' '.join(props[:10])})"
                )
            try:
                table[i] = [float(v) for v in values]
            except ValueError:
                raise DataError(f"{p}: line {line_no} (vertex {i}) holds non-numeric values") from None
    col = {name: i for i, name in enumerate(props)}
    points = np.stack([table[:, col[c]] for c in ("x", "y", "z")], axis=-1).reshape(height, width, 3)
    grey = None
    for c in ("red", "grey", "gray", "intensity"):
        if c in col:
            with np.errstate(invalid="ignore"):
                grey = np.clip(np.nan_to_num(table[:, col[c]]), 0, 255).astype(np.uint8).reshape(height, width)
            break
    return PlyCapture(p, points, grey)


def fit_intrinsics(points: np.ndarray, valid: np.ndarray | None = None) -> tuple[tuple[float, float, float, float], float]:
    """((fx, fy, cx, cy), RMS residual in px) of the pinhole that best maps points to their pixels.

    Least squares of ``u = fx * x/z + cx`` and ``v = fy * y/z + cy`` over valid pixels.
    """
    pts = np.asarray(points, dtype=np.float64)
    h, w = pts.shape[:2]
    if valid is None:
        with np.errstate(invalid="ignore"):
            valid = np.isfinite(pts).all(axis=-1) & (pts[..., 2] > 0)
    n = int(valid.sum())
    if n < _MIN_FIT_PIXELS:
        raise DataError(f"only {n} valid pixels; need >= {_MIN_FIT_PIXELS} to fit camera intrinsics")
    vv, uu = np.nonzero(valid)
    z = pts[..., 2][valid]
    out = []
    sq = 0.0
    for coord, ray in ((uu, pts[..., 0][valid] / z), (vv, pts[..., 1][valid] / z)):
        if np.ptp(ray) <= 0:
            raise DataError("valid points do not spread across the image; cannot fit camera intrinsics")
        a = np.stack([ray, np.ones_like(ray)], axis=1)
        sol, *_ = np.linalg.lstsq(a, coord.astype(np.float64), rcond=None)
        sq += float(((a @ sol - coord) ** 2).sum())
        out.append(sol)
    (fx, cx), (fy, cy) = out
    if not (fx > 0 and fy > 0):
        raise DataError(f"fitted focal lengths fx={fx:.1f}, fy={fy:.1f} are not positive; are x/y swapped?")
    return (float(fx), float(fy), float(cx), float(cy)), float(np.sqrt(sq / (2 * n)))


# -------------------------------------------------------------------------------------- writing


@dataclass(frozen=True)
class ImportSummary:
    """What an import wrote."""

    source: str
    out: Path
    frames: int
    labelled: bool
    invalid_fraction: float
    object_fraction: float | None
    intrinsics: tuple[float, float, float, float]
    extra: dict[str, Any]

    def to_dict(self) -> dict[str, Any]:
        return {
            "source": self.source,
            "out": str(self.out),
            "frames": self.frames,
            "labelled": self.labelled,
            "invalid_fraction": self.invalid_fraction,
            "object_fraction": self.object_fraction,
            "intrinsics": dict(zip(("fx", "fy", "cx", "cy"), self.intrinsics)),
            **self.extra,
        }


def _natural_key(p: Path) -> list[Any]:
    return [int(t) if t.isdigit() else t for t in re.split(r"(\d+)", p.name)]


def find_inputs(paths: Iterable[str | Path], pattern: str, what: str) -> list[Path]:
    """Files named on the command line plus the ``pattern`` matches of named directories,
    directories in natural order (scan_2 before scan_10)."""
    out: list[Path] = []
    for raw in paths:
        p = check_input_file(raw, "inputs", allow_dir=True)  # a FIFO would block the import forever
        if p.is_dir():
            found = sorted((f for f in p.glob(pattern) if f.is_file()), key=_natural_key)
            if not found:
                raise DataError(f"{p}: directory holds no {pattern} files ({what})")
            out.extend(found)
        else:
            out.append(p)
    if not out:
        raise DataError(f"no input files given ({what})")
    return out


def _check_out(out: str | Path, inputs: list[Path]) -> Path:
    """The output file, refused before any work if it is unusable or would replace an input."""
    o = Path(out)
    if o.is_dir():
        raise DataError(f"`out` {o}: is a directory; give a file name ending in .mcap")
    if o.suffix != ".mcap":
        raise DataError(f"`out` {o}: name must end in .mcap")
    if not o.parent.exists():
        raise DataError(f"`out` {o}: directory {o.parent} does not exist; create it first")
    check_outputs({"out": o}, {"inputs": inputs})
    return o


def import_blensor(
    inputs: Iterable[str | Path],
    out: str | Path,
    background_id: float | None = None,
    intrinsics: tuple[float, float, float, float] | None = None,
) -> ImportSummary:
    """Write BlenSor scans as labelled Z-depth frames (one MCAP file, frame order = file order)."""
    files = find_inputs(inputs, "scan_*.npy", "BlenSor scans")
    o = _check_out(out, files)
    scans = [read_blensor_scan(f) for f in files]
    bg = float(background_id) if background_id is not None else detect_background_id(scans)
    k = intrinsics or blensor_intrinsics()
    invalid = 0
    objects = 0
    total = 0
    with FrameWriter(o) as wr:
        for i, s in enumerate(scans):
            depth, label = blensor_frame(s, bg, k)
            invalid += int((depth <= 0).sum())
            objects += int(label.sum())
            total += depth.size
            scene = {
                "index": i,
                "seed": [],
                "params": {
                    "source": "blensor",
                    "file": s.path.name,
                    "background_id": bg,
                    "depth": "Z from BlenSor radial range: Z = r / sqrt(1 + xn^2 + yn^2)",
                    "objects": int(np.unique(s.ids[s.ids != bg]).size),
                },
            }
            wr.write(SIM_EPOCH_NS + i * FRAME_PERIOD_NS, depth, label=label, intrinsics=k, scene=scene)
    return ImportSummary(
        source="blensor",
        out=o,
        frames=len(scans),
        labelled=True,
        invalid_fraction=invalid / total,
        object_fraction=objects / total,
        intrinsics=k,
        extra={"background_id": bg},
    )


def import_ply(
    inputs: Iterable[str | Path],
    out: str | Path,
    width: int = BLENSOR_WIDTH,
    height: int = BLENSOR_HEIGHT,
    label_above_plane_m: float | None = None,
) -> ImportSummary:
    """Write royaleviewer PLY captures as Z-depth frames with fitted intrinsics.

    Args:
        inputs: .ply files or directories holding them.
        out: the .mcap file to write (atomically).
        width, height: the image size the vertices are laid out in (row-major).
        label_above_plane_m: None = no labels (real captures have none). A height h labels every
            valid pixel more than h above the dominant floor plane as object: the RANSAC plane of
            `edge.baseline.PlaneBaseline` with its 3 x 3 median on the height map. A *geometric*
            label: the plane-fit baseline nearly is the labeller, so such labels measure agreement
            with geometry, not truth (the rule goes into the scene JSON).
    """
    files = find_inputs(inputs, "*.ply", "royaleviewer PLY captures")
    o = _check_out(out, files)
    labeller = None
    if label_above_plane_m is not None:
        from edge.baseline import Intrinsics, PlaneBaseline

        labeller = PlaneBaseline(height_threshold_m=float(label_above_plane_m))
    objects = 0
    invalid = 0
    total = 0
    rms_all = []
    k_all = []
    with FrameWriter(o) as wr:
        for i, f in enumerate(files):
            cap = read_ply(f, width, height)
            k, rms = fit_intrinsics(cap.points, cap.valid)
            depth = cap.depth
            invalid += int((depth <= 0).sum())
            total += depth.size
            rms_all.append(rms)
            k_all.append(k)
            t = SIM_EPOCH_NS + i * FRAME_PERIOD_NS
            if cap.grey is not None:
                wr.write_image(TOPIC_MONO8, t, cap.grey, "mono8")
            scene = {
                "index": i,
                "seed": [],
                "params": {
                    "source": "royaleviewer-ply",
                    "file": cap.path.name,
                    "depth": "Z = PLY z",
                    "intrinsics_fit": "least squares u = fx*x/z + cx, v = fy*y/z + cy over valid pixels",
                    "intrinsics_fit_rms_px": rms,
                },
            }
            label = None
            if labeller is not None:
                label = labeller.predict(depth, Intrinsics(*k)).astype(np.uint8)
                objects += int(label.sum())
                scene["params"]["labels"] = (
                    f"geometric: > {label_above_plane_m * 1000:g} mm above the RANSAC floor plane "
                    "(edge.baseline.PlaneBaseline, 3x3 median on heights)"
                )
            wr.write(t, depth, label=label, intrinsics=k, scene=scene)
    return ImportSummary(
        source="ply",
        out=o,
        frames=len(files),
        labelled=labeller is not None,
        invalid_fraction=invalid / total,
        object_fraction=objects / total if labeller is not None else None,
        intrinsics=tuple(float(v) for v in np.mean(k_all, axis=0)),  # type: ignore[arg-type]
        extra={"intrinsics_fit_rms_px": float(np.mean(rms_all))},
    )


# ------------------------------------------------------------------------------------------- CLI

_DESCRIPTION = """\
Convert depth frames made by other tools into the depthseg MCAP layout
(/pico_flexx/image_depth 32FC1 Z metres 0 = invalid, /pico_flexx/labels, /pico_flexx/camera_info,
/depthseg/scene with the source file name).

  blensor: the seed paper's BlenSor scans (scan_*.npy, radial range + object ids) -> Z depth
           and labels (object id != ground id). Intrinsics: BlenSor's 62 x 45 deg pinhole.
  ply:     royaleviewer ASCII PLY captures of a real pico flexx -> Z depth (no labels), pinhole
           intrinsics fitted to the points, grey amplitude on /pico_flexx/image_mono8.
"""


def _parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(
        prog="depthseg-sim import",
        description=_DESCRIPTION,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    sub = ap.add_subparsers(dest="source", metavar="{blensor,ply}")
    sub.required = True
    b = sub.add_parser("blensor", help="BlenSor scan_*.npy files (the paper's dataset)")
    b.add_argument("inputs", nargs="+", help="scan_*.npy files or directories holding them (natural order)")
    b.add_argument("--out", required=True, help="output .mcap file (written atomically)")
    b.add_argument(
        "--background-id",
        type=float,
        default=None,
        help="object id of the ground (default: the id of a single-id scan, else the id covering "
        "most of the frame borders)",
    )
    b.add_argument("--json", action="store_true", help="print the summary as one JSON object")
    p = sub.add_parser("ply", help="royaleviewer ASCII PLY captures (one vertex per pixel)")
    p.add_argument("inputs", nargs="+", help=".ply files or directories holding them")
    p.add_argument("--out", required=True, help="output .mcap file (written atomically)")
    p.add_argument("--width", type=int, default=BLENSOR_WIDTH, help="image width in pixels (default 224)")
    p.add_argument("--height", type=int, default=BLENSOR_HEIGHT, help="image height in pixels (default 171)")
    p.add_argument("--label-above-plane", type=float, metavar="MM",
                   help="label pixels more than MM millimetres above the RANSAC floor plane as object "
                        "(a geometric rule, e.g. 10; default: no labels)")
    p.add_argument("--json", action="store_true", help="print the summary as one JSON object")
    return ap


def import_main(argv: list[str] | None = None) -> int:
    """``depthseg-sim import blensor|ply INPUTS --out OUT.mcap`` (argv excludes 'import')."""
    from edge.cliutil import print_json, run

    ap = _parser()
    args = ap.parse_args(argv)
    prog = f"depthseg-sim import {args.source}"

    def body() -> int:
        if args.source == "blensor":
            s = import_blensor(args.inputs, args.out, background_id=args.background_id)
        else:
            if args.width < 1 or args.height < 1:
                raise DataError(f"--width/--height must be positive, got {args.width} x {args.height}")
            mm = args.label_above_plane
            if mm is not None and not (0 < mm < 1000):
                raise DataError(f"--label-above-plane must be a height in mm in (0, 1000), got {mm}")
            s = import_ply(args.inputs, args.out, width=args.width, height=args.height,
                           label_above_plane_m=None if mm is None else mm / 1000.0)
        if args.json:
            print_json(s.to_dict())
        else:
            fx, fy, cx, cy = s.intrinsics
            what = f", object pixels {s.object_fraction:.1%}" if s.object_fraction is not None else " (no labels)"
            print(
                f"wrote {s.frames} {s.source} frames to {s.out}: invalid pixels {s.invalid_fraction:.1%}"
                f"{what}; intrinsics fx={fx:.1f} fy={fy:.1f} cx={cx:.1f} cy={cy:.1f}"
            )
        return 0

    return run(prog, body, ap, aliases={"inputs": "input"})


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(import_main())
