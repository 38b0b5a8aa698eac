#!/usr/bin/env python
"""Peak RSS and wall time of `depthseg-replay` on hostile recordings (issue 11's memory class).

Why: the tests bound Python allocations (tracemalloc) in-process; a user meets the whole
command. This builds the bombs with the test suite's own builders (tests/replay/
test_hostile_streams.py: compressed by streaming, the zeros never exist in memory), runs the
console script on each under ``/usr/bin/time`` and prints a markdown table: file size, exit code,
the error line, peak RSS (MB) and seconds. Issue 11 asks < 1 GB and < 60 s for inputs < 100 MB.

    .venv/bin/python tools/hostile_bench.py [--out DIR]     # ~1-2 min, writes ~30 MB of files
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT), str(ROOT / "tests"), str(ROOT / "tests" / "replay")]

import test_hostile_streams as H  # noqa: E402

from edge import rosmsg  # noqa: E402


def _huge_frame(path: Path, side: int) -> Path:
    n = side * side * 2
    cdr = rosmsg._W()
    cdr.header(1, "cam")
    for v in (side, side):
        cdr.u32(v)
    cdr.string("16UC1")
    cdr.u8(0)
    cdr.u32(side * 2)
    cdr.u32(n)
    return H.mcap_file(path, H._bomb_chunk("zstd", n, True, payload=cdr.bytes(), declared=-1))


def cases(d: Path) -> list[tuple[str, Path]]:
    return [
        ("MCAP zstd chunk: 1.1 GB of zeros claiming 64 bytes", H.mcap_file(d / "zstd.mcap", H._bomb_chunk("zstd", 1_100_000_000, False))),
        ("MCAP lz4 chunk: 3.15 GB of zeros claiming 64 bytes", H.mcap_file(d / "lz4.mcap", H._bomb_chunk("lz4", 3_150_000_000, False))),
        ("MCAP: one valid 8192 x 8192 16UC1 frame", _huge_frame(d / "huge.mcap", 8192)),
        ("ROS 1 bag, lz4 chunk: 1 GB of zeros behind an honest size", H.ros1_bomb_bag(d / "lz4.bag", "lz4", 1 << 30)),
        ("ROS 1 bag, bz2 chunk: 256 MB of zeros behind an honest size", H.ros1_bomb_bag(d / "bz2.bag", "bz2", 256 << 20)),
    ]


def measure(path: Path) -> tuple[int, str, float, float]:
    cmd = ["/usr/bin/time", "-f", "%M %e", str(ROOT / ".venv" / "bin" / "depthseg-replay"), str(path)]
    res = subprocess.run(cmd, capture_output=True, text=True, timeout=600)
    lines = res.stderr.strip().splitlines()
    kb, secs = lines[-1].split()
    msg = next((ln for ln in lines[:-1] if "error" in ln), lines[-2] if len(lines) > 1 else "")
    rc = res.returncode
    return rc, msg, int(kb) / 1024, float(secs)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--out", type=Path, default=None, help="keep the hostile files here (default: a temporary folder)")
    a = p.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        d = a.out or Path(tmp)
        d.mkdir(parents=True, exist_ok=True)
        print("| input | file | exit | peak RSS | seconds | message |")
        print("|---|---:|---:|---:|---:|---|")
        for name, f in cases(d):
            rc, msg, mb, secs = measure(f)
            size = f.stat().st_size
            print(f"| {name} | {size / 1024:.0f} kB | {rc} | {mb:.0f} MB | {secs:.1f} | {msg[:110]} |", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
