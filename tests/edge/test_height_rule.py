"""The minimum-object-height rule (edge.postprocess.remove_low_parts) and every path that applies it."""

from __future__ import annotations

import json

import numpy as np
import pytest
from onnxgen import linear_model

from edge.cues import fit_dominant_plane
from edge.errors import ConfigError, ModelError
from edge.infer import UNKNOWN, Segmenter
from edge.meta import ModelMeta
from edge.metrics import object_mask, segmentation_mask
from edge.postprocess import check_min_height, remove_low_parts, support_height
from edge.sampleframes import synthetic_frames


def _scene() -> tuple[np.ndarray, np.ndarray]:
    """A mask with a box (40 mm high, a 1 px fringe at 2 mm and a 6 mm base ring) and a 4 mm plate."""
    h = np.zeros((30, 40), np.float32)
    obj = np.zeros((30, 40), bool)
    obj[4:16, 4:16] = True  # the box and its fringe
    h[5:15, 5:15] = 0.006  # base ring
    h[6:14, 6:14] = 0.040  # top
    h[4, 4:16] = h[15, 4:16] = 0.002  # fringe rows at table level
    obj[20:26, 25:35] = True
    h[20:26, 25:35] = 0.004  # a plate wholly below 10 mm
    return obj, h


def test_low_parts_of_objects_reaching_over_the_line_become_table_and_low_objects_stay() -> None:
    obj, h = _scene()
    out = remove_low_parts(obj, h, 0.010)
    assert out[6:14, 6:14].all()  # the top stays
    assert not out[4:16, 4:16][~np.pad(np.ones((8, 8), bool), 2)].any()  # fringe and base ring: table
    assert out[20:26, 25:35].all()  # the plate (every pixel under the line) stays object
    assert out.sum() == 64 + 60
    assert obj.sum() == 144 + 60  # the input is not modified
    assert np.array_equal(remove_low_parts(obj, h, 0.005), obj & ~((h < 0.005) & (np.arange(30)[:, None] < 18)))
    assert remove_low_parts(obj, h, 0.0) is not None and np.array_equal(remove_low_parts(obj, h, 0.0), obj)


def test_bad_lines_and_shapes_are_refused_in_one_line() -> None:
    obj, h = _scene()
    for bad in (-0.001, 0.5, float("nan"), "x"):
        with pytest.raises(ConfigError, match="min_height_m"):
            check_min_height(bad)
    with pytest.raises(ConfigError, match="shape"):
        remove_low_parts(obj, h[:10], 0.01)
    logits = np.where(obj, 3.0, -3.0).astype(np.float32)
    with pytest.raises(ConfigError, match="height_m"):
        object_mask(logits, np.ones_like(obj), 0.5, 0, None, 0.01)


def test_masks_apply_the_height_rule_before_the_speck_rule() -> None:
    obj, h = _scene()
    obj[17, 2] = True  # a 1 px speck at table level, alone: wholly low, so only the speck rule removes it
    logits = np.where(obj, 3.0, -3.0).astype(np.float32)
    valid = np.ones(obj.shape, bool)
    valid[0, 0] = False
    got = object_mask(logits, valid, 0.5, 6, h, 0.010)
    assert got.sum() == 64 + 60 and not got[17, 2]
    seg = segmentation_mask(logits, valid, 0.5, 6, h, 0.010)
    assert seg[0, 0] == UNKNOWN and np.array_equal(seg[valid] == 1, got[valid])


def test_support_height_is_the_height_cue_plane_in_metres() -> None:
    d = synthetic_frames(1, 3).depth[0]
    valid = d > 0
    h = support_height(d, valid)
    fit = fit_dominant_plane(d, valid)
    expect = np.clip(fit.depth(d.shape) - d, -0.1, 0.3)
    np.testing.assert_allclose(h[valid], expect[valid], atol=1e-5)
    assert h.dtype == np.float32 and (h[~valid] == 0).all()


def test_metadata_carries_the_rule_and_old_models_keep_their_bytes() -> None:
    assert ModelMeta().min_height_m == 0.0 and "min_height_m" not in ModelMeta().to_dict()
    m = ModelMeta(min_height_m=0.01)
    assert ModelMeta.from_json(m.to_json()).min_height_m == 0.01
    assert "under 10 mm" in m.onnx_props()["postprocessing"]
    for bad in (-0.01, 0.3, True, "0.01"):
        with pytest.raises(ModelError, match="min_height_m"):
            ModelMeta(min_height_m=bad)


@pytest.mark.parametrize("stored", [0.0, 0.01])
def test_segmenter_applies_the_stored_rule_or_an_override(tmp_path, stored) -> None:
    path = linear_model(tmp_path / "m.onnx", bias=1.2)
    if stored:  # the rule stored in the model's metadata, as `depthseg-export --min-height-mm` does
        import onnx

        from edge.meta import META_KEY

        mod = onnx.load(str(path))
        props = {p.key: p for p in mod.metadata_props}
        meta = ModelMeta.from_json(props[META_KEY].value).with_(min_height_m=stored)
        props[META_KEY].value = meta.to_json()
        onnx.save(mod, str(path))
    d = synthetic_frames(2, 5).depth[1]
    on = Segmenter(path, threads=1) if stored else Segmenter(path, threads=1, min_height_m=0.01)
    off = Segmenter(path, threads=1, min_height_m=0.0)
    p, q = on.predict(d), off.predict(d)
    assert on.min_height_m == 0.01 and off.min_height_m == 0.0 and q.height_m is None
    np.testing.assert_array_equal(p.height_m, support_height(d, p.valid))
    want = segmentation_mask(q.logits, q.valid, on.threshold, on.min_object_px, p.height_m, 0.01)
    np.testing.assert_array_equal(p.mask, want)
    assert (p.mask == 1).sum() < (q.mask == 1).sum()  # the rule removed something: not vacuous


def test_eval_cli_reports_the_rule_and_refuses_bad_millimetres(capsys, linear_onnx, tmp_path) -> None:
    from replaygen import scene

    from edge.eval_cli import main
    from edge.io import FrameWriter
    from edge.meta import fov_intrinsics

    data = tmp_path / "a.mcap"
    with FrameWriter(data) as w:
        for i in range(3):
            d, lab = scene(i, 64, 96, box=True)
            w.write(i * 100_000_000, d, lab, intrinsics=fov_intrinsics(96, 64, 62.0, 45.0))
    scores = {}
    for mm in ("0", "10"):
        rc = main(["--model", str(linear_onnx), "--data", str(data), "--min-height-mm", mm, "--json"])
        out = capsys.readouterr()
        assert rc == 0, out.err
        scores[mm] = json.loads(out.out)
    assert scores["0"]["min_height_m"] == 0.0 and scores["10"]["min_height_m"] == 0.01
    with pytest.raises(SystemExit) as e:
        main(["--model", str(linear_onnx), "--data", str(data), "--min-height-mm", "-3"])
    err = capsys.readouterr().err
    assert e.value.code == 2 and "--min-height-mm" in err and "from 0 (off) to 200 mm" in err and "Traceback" not in err


def test_declared_labels_are_read_from_both_layouts() -> None:
    from edge.evaluate import declared_labels, labels_line_mm

    text = "geometric: > 10 mm above the RANSAC floor plane"
    assert declared_labels({"labels": text}) == text == declared_labels({"params": {"labels": text}})
    assert declared_labels(None) is None and declared_labels({"params": {"seed": 1}}) is None
    assert declared_labels({"labels": ["not", "text"]}) is None and declared_labels({"params": "x"}) is None
    assert len(declared_labels({"labels": "x" * 10_000})) == 200
    assert labels_line_mm(text) == 10.0 and labels_line_mm("geometric: > 7.5 mm above it") == 7.5
    assert labels_line_mm("simulator ids") is None


def test_eval_names_the_labels_meaning_and_the_flag_for_it(capsys, linear_onnx, tmp_path) -> None:
    from replaygen import scene

    from edge.eval_cli import main
    from edge.io import FrameWriter
    from edge.meta import fov_intrinsics

    data = tmp_path / "geo.mcap"
    with FrameWriter(data) as w:
        for i in range(2):
            d, lab = scene(i, 64, 96, box=True)
            w.write(i * 100_000_000, d, lab, intrinsics=fov_intrinsics(96, 64, 62.0, 45.0),
                    scene={"index": i, "params": {"labels": "geometric: > 10 mm above the RANSAC floor plane"}})
    assert main(["--model", str(linear_onnx), "--data", str(data)]) == 0
    out = capsys.readouterr().out
    assert "labels, as the recording describes them: geometric: > 10 mm" in out
    assert "--min-height-mm 10 scores the model with the labels' meaning" in out
    assert main(["--model", str(linear_onnx), "--data", str(data), "--min-height-mm", "10", "--json"]) == 0
    d = json.loads(capsys.readouterr().out)
    assert d["labels_declared"] == ["geometric: > 10 mm above the RANSAC floor plane"] and d["min_height_m"] == 0.01


def test_a_model_with_the_height_cue_reuses_it_and_a_raw_graph_fits_the_plane(tmp_path) -> None:
    # the shipped model takes the height cue: the rule reads that channel (no second plane fit);
    # a --with-preprocessing graph without a height output fits the plane itself: same heights
    from onnxgen import raw_model

    d = synthetic_frames(1, 11).depth[0]
    shipped = Segmenter(None, threads=1, min_height_m=0.01)
    assert "height" in shipped.meta.cues
    p = shipped.predict(d)
    np.testing.assert_array_equal(p.height_m, support_height(d, p.valid))
    raw = Segmenter(raw_model(tmp_path / "raw.onnx", height=d.shape[0], width=d.shape[1]), threads=1, min_height_m=0.01)
    q = raw.predict(d)
    assert raw.with_preprocessing and not raw.has_height_output and raw.graph_height(d) is None
    np.testing.assert_array_equal(q.height_m, support_height(d, q.valid))


def test_a_graph_with_a_height_output_gives_the_rule_its_heights(tmp_path) -> None:
    # a --with-preprocessing graph of a model with the height cue returns that cue in metres:
    # the rule takes it as it is (the plane the network saw), with no second fit in numpy
    from onnxgen import raw_model

    d = synthetic_frames(1, 11).depth[0]  # table 0.22-0.23 m away, objects ~10 cm nearer
    cut = 0.232  # a flat support just behind most of the table: those table pixels are low "objects"
    seg = Segmenter(raw_model(tmp_path / "h.onnx", cut, d.shape[0], d.shape[1], height_output="cut"),
                    threads=1, min_height_m=0.01)
    p = seg.predict(d)
    expect = np.where(np.isfinite(d) & (d > 0), np.float32(cut) - d, np.float32(0.0))
    np.testing.assert_array_equal(p.height_m, expect)
    assert seg.has_height_output and np.array_equal(seg.graph_height(d), expect)  # the same output, alone
    assert not np.array_equal(p.height_m, support_height(d, p.valid))  # the graph's, not a refit
    low = p.valid & (p.prob >= 0.5) & (p.height_m < 0.01)
    assert low.any() and not (p.mask[low] == 1).any()  # the rule ran on the graph's heights


@pytest.mark.parametrize("kind", ["nan", "row"])
def test_a_broken_height_output_is_a_one_line_model_error(tmp_path, kind) -> None:
    from onnxgen import raw_model

    d = synthetic_frames(1, 11).depth[0]
    path = raw_model(tmp_path / f"{kind}.onnx", height=d.shape[0], width=d.shape[1], height_output=kind)
    with pytest.raises(ModelError, match="'height' output is not a finite float map"):
        Segmenter(path, threads=1, min_height_m=0.01).predict(d)
    assert Segmenter(path, threads=1).predict(d).height_m is None  # rule off: the output is not read


def test_both_paths_agree_with_a_plain_labelling() -> None:
    # few components (8-bit lookup path) and many (general path) against plain numpy
    import cv2

    rng = np.random.default_rng(5)
    for t in range(200):
        hh, ww = rng.integers(1, 150, 2)
        m = rng.random((hh, ww)) < rng.uniform(0.0, 0.8)
        height = rng.uniform(-0.005, 0.03, (hh, ww)).astype(np.float32)
        n, lab = cv2.connectedComponents(m.view(np.uint8), connectivity=8, ltype=cv2.CV_32S)
        low = m & (height < 0.01)
        reaches = np.zeros(n, bool)
        reaches[lab[m & ~low]] = True
        reaches[0] = False
        np.testing.assert_array_equal(remove_low_parts(m, height, 0.01), m & ~(low & reaches[lab]), err_msg=f"case {t}")
