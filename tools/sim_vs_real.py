#!/usr/bin/env python
"""The README figure: a simulated frame beside the real pico flexx capture, with numbers.

Why: the paper's model failed on real frames because its BlenSor data had none of the real
sensor's artefacts (section V.e). This puts our simulator next to the real capture in
``../shared/data/royale`` and measures both with the same code (`sim.realism`): invalid-pixel
fraction and where it lies (corners / object edges / elsewhere, per-corner fill), floor noise
sigma, flying pixels at edges. The simulated scenes use the default Table I configuration with
the camera fixed at the real capture's height (30 cm); the figure shows the first of them with
6-12 objects (``--objects``; the real scene holds ~9), and the table adds the mean +- sd over
``--frames`` frames.

The edge-model fit (issue 9): ``tools/test_configs/real_sensor_edges.json`` is the sensor at the
real end of the training range (PSF 0.4 px, 3 % of flying pixels missed by the filter) on Table I
scenes of 8-12 objects, like the real ~9; the last column (sim median / real) shows each number's
ratio. Edge-pixel counts depend on how much object outline a scene holds, so sharpness is compared
per outline pixel (`sim.realism.edge_sharpness`).

Writes ``docs/sim_vs_real.png`` (figure) and ``docs/sim_vs_real.md`` (table + this command),
and prints the table. The real capture is read at run time and never copied into the repo.

    .venv/bin/python tools/sim_vs_real.py --config tools/test_configs/real_sensor_edges.json --frames 32
"""

from __future__ import annotations

import argparse
import sys
from dataclasses import replace
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:  # run as a script from a checkout
    sys.path.insert(0, str(ROOT))

import numpy as np  # noqa: E402

from edge.cliutil import print_json, run  # noqa: E402
from edge.errors import ConfigError, DataError  # noqa: E402
from edge.io import atomic_write, write_bytes_atomic  # noqa: E402
from edge.preprocess import valid_mask  # noqa: E402
from sim.realism import CORNERS, Realism, flying_pixels, invalid_regions, realism  # noqa: E402

PROG = "sim_vs_real"
DEFAULT_REAL = ROOT.parent / "shared" / "data" / "royale" / "royale_20200513_203219_0.ply"
REAL_HEIGHT_M = 0.30  # the paper (V.e): captured from ~30 cm

# (key, label, unit scale, format): the rows of the table, read from Realism.to_dict()
ROWS = [
    ("invalid.fraction", "invalid pixels, % of frame", 100, "{:.2f}"),
    ("invalid.corner_share", "  of which in the corners, %", 100, "{:.0f}"),
    ("invalid.edge_share", "  of which at object edges, %", 100, "{:.0f}"),
    ("invalid.other_share", "  of which elsewhere, %", 100, "{:.0f}"),
    ("edges.invalid_per_edge_pixel", "invalid edge pixels per valid edge pixel", 1, "{:.3f}"),
    *[(f"invalid.corner_fill.{c}", f"corner {c}: % of its region invalid", 100, "{:.1f}") for c in CORNERS],
    ("noise.sigma_patch", "floor noise sigma (8x8 plane fits), mm", 1000, "{:.2f}"),
    ("noise.sigma_diff", "floor noise sigma (neighbour diff.), mm", 1000, "{:.2f}"),
    ("noise.correlation_ratio", "  ratio diff / patch (1 = white noise)", 1, "{:.2f}"),
    ("flying.edge_pixels", "edge pixels (4-neighbour step > 18 mm)", 1, "{:.0f}"),
    ("edges.outline_pixels", "  object outline pixels (next to the floor)", 1, "{:.0f}"),
    ("edges.sharpness", "  edge pixels per outline pixel", 1, "{:.2f}"),
    ("flying.fraction", "flying pixels, % of edge pixels", 100, "{:.2f}"),
]


def _flat(r: Realism) -> dict[str, float]:
    d = r.to_dict()
    out: dict[str, float] = {}

    def walk(prefix: str, obj) -> None:
        for k, v in obj.items():
            key = f"{prefix}{k}"
            if isinstance(v, dict):
                walk(key + ".", v)
            else:
                out[key] = float(v)

    walk("", d)
    sp, sd = out["noise.sigma_patch"], out["noise.sigma_diff"]
    out["noise.correlation_ratio"] = sd / sp if sp > 0 else float("nan")
    return out


def real_frame(path: Path) -> tuple[np.ndarray, tuple[float, float, float, float]]:
    from sim.importers import fit_intrinsics, read_ply

    if not path.exists():
        raise DataError(f"{path}: real capture not found; pass --real PATH to a royaleviewer PLY")
    cap = read_ply(path)
    k, _ = fit_intrinsics(cap.points, cap.valid)
    return cap.depth, k


def sim_frames(seed: int, n: int, height: float, config: Path | None = None):
    """(frame, objects) of the default Table I configuration (or ``config``), camera at ``height``."""
    import json

    from sim.generate import SimConfig, generate_frame

    base = SimConfig.from_dict(json.loads(config.read_text())) if config else SimConfig.from_dict({"scene": {"views_per_scene": 1}})
    cfg = replace(base, scene=replace(base.scene, camera_height_m=(height, height)))
    for i in range(n):
        f = generate_frame(i, seed, cfg)
        yield f, len(f.scene["params"]["objects"])


def cells(real: dict[str, float], shown: dict[str, float], many: list[dict[str, float]]) -> list[tuple[str, ...]]:
    """Per row of ROWS: label, real, shown sim frame, sim mean ± sd, sim median / real (formatted once)."""
    out = []
    for key, label, scale, fmt in ROWS:
        vals = np.array([m[key] for m in many]) * scale
        ratio = np.nanmedian(vals) / (real[key] * scale) if real[key] else float("nan")
        out.append((
            label.strip(),
            fmt.format(real[key] * scale),
            fmt.format(shown[key] * scale),
            f"{fmt.format(np.nanmean(vals))} ± {fmt.format(np.nanstd(vals))}",
            f"{ratio:.2f}",
        ))  # fmt: skip
    return out


def table(real: dict[str, float], shown: dict[str, float], shown_index: int, many: list[dict[str, float]]) -> str:
    head = (
        f"| metric | real capture | sim frame {shown_index} | sim mean ± sd ({len(many)} frames) | sim median / real |\n"
        "|---|---:|---:|---:|---:|\n"
    )
    return head + "\n".join("| " + " | ".join(row) + " |" for row in cells(real, shown, many)) + "\n"


def _panel(depth: np.ndarray, lo: float, hi: float) -> np.ndarray:
    import matplotlib

    valid = valid_mask(depth)
    t = np.clip((hi - np.where(valid, depth, hi)) / (hi - lo), 0, 1)
    rgb = matplotlib.colormaps["viridis"](t)[..., :3]
    rgb[~valid] = 0.0
    return rgb


def _regions_panel(depth: np.ndarray) -> np.ndarray:
    valid = valid_mask(depth)
    d = np.where(valid, depth, np.nan)
    grey = np.clip((np.nanmax(d) - np.nan_to_num(d, nan=np.nanmax(d))) / max(np.nanmax(d) - np.nanmin(d), 1e-6), 0, 1)
    rgb = np.repeat((0.25 + 0.5 * grey)[..., None], 3, axis=2)
    reg = invalid_regions(depth)
    rgb[reg["corner"]] = (0.85, 0.1, 0.1)
    rgb[reg["edge"]] = (1.0, 0.6, 0.0)
    rgb[reg["other"]] = (0.0, 0.8, 1.0)
    rgb[flying_pixels(depth)[1]] = (1.0, 0.0, 1.0)
    return rgb


def figure(
    real: np.ndarray,
    sim: np.ndarray,
    rows: list[tuple[str, str, str, str]],
    sim_title: str,
    short_title: str,
    out: Path,
) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    both = np.concatenate([real[real > 0], sim[sim > 0]])
    lo, hi = np.percentile(both, [2, 98])
    fig = plt.figure(figsize=(8.6, 10.2))
    gs = fig.add_gridspec(4, 2, height_ratios=[1, 1, 0.12, 1.1], hspace=0.2, wspace=0.04)
    panels = [
        (_panel(real, lo, hi), "real pico flexx (royaleviewer PLY), Z"),
        (_panel(sim, lo, hi), f"{sim_title}, Z"),
        (_regions_panel(real), "real: invalid pixels by region"),
        (_regions_panel(sim), "sim: invalid pixels by region"),
    ]
    for k, (img, title) in enumerate(panels):
        ax = fig.add_subplot(gs[k // 2, k % 2])
        ax.imshow(img, interpolation="nearest")
        ax.set_title(title, fontsize=10)
        ax.set_xticks([])
        ax.set_yticks([])
    ax = fig.add_subplot(gs[2, :])
    ax.axis("off")
    ax.text(
        0.5, 0.5,
        f"Z colour scale {lo * 100:.0f} cm (yellow) to {hi * 100:.0f} cm (blue), invalid black.\n"
        "Invalid pixels: corner (red), object edge (orange), other (cyan); flying pixels (magenta).",
        ha="center", va="center", fontsize=8.5, transform=ax.transAxes,
    )  # fmt: skip
    ax = fig.add_subplot(gs[3, :])
    ax.axis("off")
    tab = ax.table(
        cellText=[list(r) for r in rows],
        colLabels=["metric", "real", short_title, "sim mean ± sd"],
        loc="upper center",
        cellLoc="center",
        colWidths=[0.42, 0.16, 0.16, 0.2],
    )
    tab.auto_set_font_size(False)
    tab.set_fontsize(8)
    tab.scale(1, 1.2)
    for (r, c), cell in tab.get_celld().items():
        if c == 0 and r > 0:
            cell.set_text_props(ha="left")
            cell.PAD = 0.02
    try:
        with atomic_write(out) as tmp:
            fig.savefig(tmp, format="png", dpi=88, bbox_inches="tight", pil_kwargs={"optimize": True})
    finally:
        plt.close(fig)


def _write_text(path: Path, text: str) -> None:
    write_bytes_atomic(path, text.encode())


parser = argparse.ArgumentParser(
    prog=PROG,
    description="Simulated frame beside the real pico flexx capture, with realism numbers side by side "
    "(invalid-pixel fraction and location, floor noise sigma, flying pixels). Writes a PNG figure and a "
    "markdown table.",
)
parser.add_argument("--real", type=Path, default=DEFAULT_REAL, help="royaleviewer ASCII PLY (default: the shared capture)")
parser.add_argument("--seed", type=int, default=0, help="simulator seed (default 0)")
parser.add_argument("--frames", type=int, default=16, help="simulated frames for the mean column (default 16)")
parser.add_argument(
    "--objects",
    type=int,
    nargs=2,
    default=(6, 12),
    metavar=("MIN", "MAX"),
    help="show the first sim frame with MIN..MAX objects, like the real scene's ~9 (default 6 12)",
)
parser.add_argument("--height", type=float, default=REAL_HEIGHT_M, help="sim camera height in m (default 0.30)")
parser.add_argument("--config", type=Path, help="simulator config JSON (as depthseg-sim --config; default: defaults)")
parser.add_argument("--png", type=Path, default=ROOT / "docs" / "sim_vs_real.png", help="figure output")
parser.add_argument("--md", type=Path, default=ROOT / "docs" / "sim_vs_real.md", help="markdown output")
parser.add_argument("--json", action="store_true", help="print all numbers as one JSON object instead of the table")


def main(argv: list[str] | None = None) -> int:
    args = parser.parse_args(argv)

    def body() -> int:
        if args.frames < 1:
            raise ConfigError(f"--frames must be >= 1, got {args.frames}")
        if not 0.1 <= args.height <= 1.0:
            raise ConfigError(f"--height must lie in [0.1, 1.0] m, got {args.height}")
        for p in (args.png, args.md):
            if p.is_dir() or not p.parent.exists():
                raise ConfigError(f"{p}: not a file path in an existing directory")
        real_depth, real_k = real_frame(args.real)
        real = _flat(realism(real_depth, real_k))
        many, shown, shown_frame = [], None, None
        for f, n_obj in sim_frames(args.seed, args.frames, args.height, args.config):
            m = _flat(realism(f.depth, f.intrinsics, seed=f.index))
            many.append(m)
            if shown is None and args.objects[0] <= n_obj <= args.objects[1]:
                shown, shown_frame = m, f
        if shown is None:  # no frame had enough objects: show the first
            shown_frame = next(sim_frames(args.seed, 1, args.height, args.config))[0]
            shown = many[0]
        idx = shown_frame.index
        md_table = table(real, shown, idx, many)
        cmd = "    .venv/bin/python tools/sim_vs_real.py " + " ".join(
            argv if argv is not None else sys.argv[1:]
        )
        n_obj = len(shown_frame.scene["params"]["objects"])
        sim_title = f"sim frame {idx} (seed {args.seed}, {n_obj} objects)"
        rows = [row[:4] for row in cells(real, shown, many)]
        figure(real_depth, shown_frame.depth, rows, sim_title, f"sim frame {idx}", args.png)
        md = (
            "# Simulated vs real pico flexx frame\n\n"
            f"![sim vs real]({args.png.name})\n\n"
            f"Real: `{args.real.name}` (royaleviewer PLY, camera ~30 cm above a parquet floor; intrinsics "
            "fitted to its points). Sim: Table I scenes of "
            + (f"`{args.config}`" if args.config else "the default configuration")
            + " with the camera at "
            f"{args.height * 100:.0f} cm, seed {args.seed}, frames 0-{args.frames - 1}; the figure shows "
            f"frame {idx} ({n_obj} objects); simulator config digest "
            f"`{shown_frame.scene['params'].get('config_digest', '?')}`. Metrics: `sim/realism.py` (definitions in its docstring), "
            "identical code for both.\n\n"
            + md_table
            + "\nMade by:\n\n"
            + cmd.rstrip()
            + "\n"
        )
        _write_text(args.md, md)
        if args.json:
            print_json({"real": real, "sim_shown": shown, "sim_index": idx, "sim_frames": many})
        else:
            print(md_table, end="")
            print(f"wrote {args.png} ({args.png.stat().st_size / 1024:.0f} kB) and {args.md}")
        return 0

    return run(PROG, body)


if __name__ == "__main__":
    raise SystemExit(main())
