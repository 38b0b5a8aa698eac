"""tools/train_step_bench.py: both layouts and bf16 run the same steps and are reported side by side."""

from __future__ import annotations

from toolmod import load_tool


def test_both_memory_formats_are_timed_and_their_losses_agree(tmp_path, capsys):
    mod = load_tool("train_step_bench.py")
    argv = ["--data", str(tmp_path / "absent"), "--frames", "4", "--steps", "2", "--warmup", "0",
            "--block", "1", "--batch-size", "2", "--threads", "1"]
    assert mod.main(argv) == 0
    out = capsys.readouterr().out
    assert "4 synthetic frames (seed 0)" in out
    rows = {line.split()[0]: line.split() for line in out.splitlines()
            if line.startswith(("channels_last", "contiguous", "bf16"))}
    assert set(rows) == {"channels_last", "contiguous", "bf16"}
    assert rows["channels_last"][4] == "1.00"  # the first variant is the reference of the ratio column
    diff = float(out.split("differs by ", 1)[1].split()[0])
    assert diff < 1e-3  # two steps of the same batches: the same loss to rounding
    rel = float(out.split("differs from float32's by ", 1)[1].split()[0])
    assert rel < 2.0  # bf16: the same loss to its 8-bit mantissa, in %


def test_the_variants_chosen_are_the_ones_timed(tmp_path, capsys):
    mod = load_tool("train_step_bench.py")
    argv = ["--data", str(tmp_path / "absent"), "--frames", "4", "--steps", "1", "--warmup", "0",
            "--block", "1", "--batch-size", "2", "--threads", "1", "--variants", "bf16", "channels_last"]
    assert mod.main(argv) == 0
    out = capsys.readouterr().out
    rows = [line.split() for line in out.splitlines() if line.startswith(("channels_last", "contiguous", "bf16"))]
    assert [r[0] for r in rows] == ["bf16", "channels_last"]
    assert rows[0][4] == "1.00"
    assert "between the layouts" not in out  # one float32 variant: no layout pair to compare


def test_crop_variants_step_on_windows_and_bad_windows_are_one_line(tmp_path, capsys):
    mod = load_tool("train_step_bench.py")
    base = ["--data", str(tmp_path / "absent"), "--frames", "4", "--steps", "1", "--warmup", "0",
            "--block", "1", "--batch-size", "2", "--threads", "1", "--variants", "channels_last"]
    assert mod.main(base + ["--crops", "64x96"]) == 0
    out = capsys.readouterr().out
    rows = [line.split() for line in out.splitlines() if line.startswith(("channels_last", "crop"))]
    assert [r[0] for r in rows] == ["channels_last", "crop64x96"]
    assert float(rows[1][4]) > 0  # timed, with its ratio to the whole frames
    assert mod.main(base + ["--crops", "992x96"]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "larger than the frames" in err and "Traceback" not in err


def test_the_pooled_band_variant_leaves_the_library_band_in_place(tmp_path, capsys):
    import edge.train.distributed as distributed
    from edge.train.losses import boundary_band

    mod = load_tool("train_step_bench.py")
    argv = ["--data", str(tmp_path / "absent"), "--frames", "4", "--steps", "1", "--warmup", "0",
            "--block", "1", "--batch-size", "2", "--threads", "1", "--variants", "channels_last", "pool_band"]
    assert mod.main(argv) == 0
    assert "pool_band's loss after the same steps equals channels_last's" in capsys.readouterr().out
    assert distributed.boundary_band is boundary_band  # a later training in this process uses the box sums
