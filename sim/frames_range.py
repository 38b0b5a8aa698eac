"""``depthseg-sim --frames-range A:B`` (`frames_range`): one array job of a batch scheduler makes shards [A, B).

Why ranges on shard boundaries: a shard is the unit of atomic output, so two jobs never write
the same file. Jobs of one array write into one ``--out`` at the same time, so a job

- deletes only its own temporary files (another job's are still being written),
- writes ``manifest.json`` (the dataset's identity: seed, config, shard size) only if it does
  not exist yet, else checks it, and
- writes its shard statistics to its own ``manifest.frames_A_B.json``.

A final run of the same command without ``--frames-range`` generates whatever is missing and
merges the parts into ``manifest.json``.

Example (SLURM, 1M frames in 100 jobs of 10,000)::

    #SBATCH --array=0-99 --cpus-per-task=8
    A=$((SLURM_ARRAY_TASK_ID * 10000)); B=$((A + 10000))
    depthseg-sim --out /shared/sim1m --frames 1000000 --seed 7 --workers 8 --frames-range $A:$B
"""

from __future__ import annotations

import json
import os
import re
from collections.abc import Callable
from pathlib import Path
from typing import Any

from edge.errors import ConfigError

__all__ = ["parse_range", "check_range", "in_range", "tmp_in_range", "part_name", "write_identity_once", "remove_orphan_tmp",
           "merge_part_stats"]

_TMP = re.compile(r"^\.frames_(\d{8})_(\d{8})\.mcap\.\d+\.tmp$")
_PART = re.compile(r"^manifest\.frames_(\d{8})_(\d{8})\.json$")


def parse_range(text: str) -> tuple[int, int]:
    """'A:B' -> (A, B)."""
    try:
        a, b = (int(v) for v in str(text).split(":"))
    except ValueError:
        shown = str(text) if len(str(text)) <= 40 else str(text)[:37] + "..."
        raise ConfigError(f"`frames_range` must be START:STOP with whole numbers, e.g. 0:1000; got '{shown}'") from None
    return a, b


def check_range(r: tuple[int, int], frames: int, shard_frames: int) -> None:
    a, b = r
    if not 0 <= a < b <= frames:
        raise ConfigError(f"`frames_range` {a}:{b} must satisfy 0 <= START < STOP <= `frames` ({frames})")
    for name, v in (("START", a), ("STOP", b)):
        if v % shard_frames and v != frames:
            lo = v - v % shard_frames
            raise ConfigError(
                f"`frames_range` {name} {v} is not on a shard boundary (`shard_frames` {shard_frames}); use {lo} or "
                f"{min(lo + shard_frames, frames)}"
            )


def in_range(shard: tuple[int, int], r: tuple[int, int]) -> bool:
    return r[0] <= shard[0] and shard[1] <= r[1]


def tmp_in_range(name: str, r: tuple[int, int]) -> bool:
    m = _TMP.match(name)
    return bool(m) and in_range((int(m.group(1)), int(m.group(2))), r)


def part_name(r: tuple[int, int]) -> str:
    return f"manifest.frames_{r[0]:08d}_{r[1]:08d}.json"


def write_identity_once(path: Path, manifest: dict[str, Any], write: Callable[[Path, Any], None]) -> None:
    """Create ``manifest.json`` unless it exists (jobs of one array agree on it; checked before)."""
    if path.exists():
        old = json.loads(path.read_text())
        if old.get("frames") != manifest["frames"]:
            raise ConfigError(
                f"{path.parent} is a dataset of {old.get('frames')} frames, not {manifest['frames']}; use the same "
                "`frames` in every job of the array"
            )
        return
    write(path, manifest)


def merge_part_stats(out: Path, stats: dict[str, dict]) -> dict[str, dict]:
    """Shard statistics of ``manifest.json`` plus those of every array job's part file."""
    merged = dict(stats)
    for p in sorted(out.iterdir()):
        if _PART.match(p.name):
            try:
                merged.update(json.loads(p.read_text()).get("shards") or {})
            except (OSError, json.JSONDecodeError):
                continue  # a part is only statistics; the shards themselves are on disk
    return merged


def remove_orphan_tmp(out: Path) -> None:
    """After a complete run: temporary files of workers that were killed (Ray retried them)."""
    for p in out.iterdir():
        if _TMP.match(p.name):
            try:
                os.unlink(p)
            except FileNotFoundError:
                pass
