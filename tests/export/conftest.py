"""Tiny exports for the export tests: each dynamo export costs seconds, so export once.

Torch runs single-threaded here (`tinymodel.one_torch_thread`); the previous setting is restored
after each use.
"""

from __future__ import annotations

import pytest
from tinymodel import one_torch_thread, tiny_model

from export.onnx_export import export_onnx
from export.preproc_graph import export_with_preprocessing
from export.single_channel import to_single_channel


@pytest.fixture(autouse=True)
def _one_torch_thread():
    with one_torch_thread():
        yield


@pytest.fixture(scope="session")
def tiny1():
    """(single-channel model, meta) of the shared tiny builder (`tinymodel.tiny_model`) at seed 1 and the
    paper's 171 x 224 sensor, not the shared 48 x 64 ``tiny_pt``: the fixed-size with-preprocessing
    graph below must take the 171 x 224 BlenSor and dead-pixel frames."""
    with one_torch_thread():
        return to_single_channel(*tiny_model(1, in_channels=3))


@pytest.fixture(scope="session")
def plain_onnx(tiny1, tmp_path_factory):
    model, meta = tiny1
    with one_torch_thread():
        return export_onnx(model, meta, tmp_path_factory.mktemp("plain") / "tiny.onnx")


@pytest.fixture(scope="session")
def edge_onnx(tiny1, tmp_path_factory):
    model, meta = tiny1
    with one_torch_thread():
        return export_with_preprocessing(model, meta, tmp_path_factory.mktemp("edge") / "tiny-pre.onnx")
