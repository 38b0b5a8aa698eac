"""The speck rule (edge.postprocess) and the metadata that carries it (ModelMeta.min_object_px)."""

from __future__ import annotations

import numpy as np
import pytest

from edge.errors import ConfigError, ModelError
from edge.meta import ModelMeta
from edge.metrics import UNKNOWN, object_mask, segmentation_mask
from edge.postprocess import remove_specks


def _mask() -> np.ndarray:
    m = np.zeros((20, 30), bool)
    m[2:6, 2:6] = True  # 16 px: kept
    m[10, 10] = True  # 1 px: removed
    m[12:14, 20:22] = True  # 4 px: removed at 6, kept at 4
    m[15, 5] = m[16, 6] = m[17, 7] = m[18, 8] = m[19, 9] = m[18, 10] = True  # 6 px, diagonal: 8-connected, kept
    return m


def test_components_under_min_px_become_background() -> None:
    m = _mask()
    out = remove_specks(m, 6)
    assert out[2:6, 2:6].all() and not out[10, 10] and not out[12:14, 20:22].any()
    assert out[15, 5] and out[18, 10]  # diagonal neighbours are one component of 6
    assert out.sum() == 16 + 6
    assert remove_specks(m, 4).sum() == 16 + 4 + 6
    assert m.sum() == 16 + 1 + 4 + 6  # the input is not modified


def test_zero_and_one_keep_everything_and_negative_is_refused() -> None:
    m = _mask()
    assert remove_specks(m, 0) is not None and np.array_equal(remove_specks(m, 0), m)
    assert np.array_equal(remove_specks(m, 1), m)
    assert not remove_specks(np.zeros((4, 4), bool), 6).any()
    with pytest.raises(ConfigError, match="min_object_px"):
        remove_specks(m, -1)


def test_more_components_than_16_bit_labels_hold() -> None:
    # a grid of isolated pixels: 86,400 components, beyond uint16 labels
    m = np.zeros((600, 600), bool)
    m[::2, ::2] = True
    m[480:, 480:] = False  # 86,400 isolated pixels remain
    m[500:510, 500:510] = True  # one 100 px blob, clear of the grid
    out = remove_specks(m, 6)
    assert out.sum() == 100 and out[500:510, 500:510].all()


def test_masks_apply_the_rule_after_the_threshold_on_valid_pixels_only() -> None:
    logits = np.where(_mask(), 3.0, -3.0).astype(np.float32)
    valid = np.ones(logits.shape, bool)
    valid[2:6, 4:6] = False  # the 16 px square loses 8 valid pixels: 8 remain, still >= 6
    valid[15:20, :] = False  # the diagonal loses its pixels: gone
    om = object_mask(logits, valid, 0.5, 6)
    assert om.sum() == 8 and not om[~valid].any()
    seg = segmentation_mask(logits, valid, 0.5, 6)
    assert (seg[~valid] == UNKNOWN).all() and (seg[valid] == om[valid]).all()
    assert object_mask(logits, valid, 0.5, 0).sum() == 8 + 1 + 4


def test_metadata_carries_the_rule() -> None:
    assert ModelMeta().min_object_px == 6
    d = ModelMeta(min_object_px=0).to_dict()
    assert d["min_object_px"] == 0 and ModelMeta.from_dict(d).min_object_px == 0
    old = ModelMeta().to_dict()
    del old["min_object_px"]  # a model from before the rule
    assert ModelMeta.from_dict(old).min_object_px == 6
    assert "6 px" in ModelMeta().onnx_props()["postprocessing"]
    for bad in (-1, 1.5, True, "6", 10**9):
        with pytest.raises(ModelError, match="min_object_px"):
            ModelMeta(min_object_px=bad)


def test_both_paths_agree_with_a_plain_labelling() -> None:
    # few components (8-bit lookup path) and many (general path) against scipy-free plain numpy
    import cv2

    rng = np.random.default_rng(3)
    for t in range(300):
        h, w = rng.integers(1, 120, 2)
        m = rng.random((h, w)) < rng.uniform(0.0, 0.7)
        n, lab = cv2.connectedComponents(m.view(np.uint8), connectivity=8, ltype=cv2.CV_32S)
        area = np.bincount(lab.ravel(), minlength=n)
        for k in (2, 6, 15):
            keep = area >= k
            keep[0] = False
            np.testing.assert_array_equal(remove_specks(m, k), keep[lab], err_msg=f"case {t}, min_px {k}")
