"""Shared tiny exports for the export tests: each dynamo export costs seconds, so export once.

Torch runs single-threaded here: on a loaded 2-core machine its OpenMP workers spin and cost
~10x the CPU time for these tiny models. The previous setting is restored after each use.
"""

from __future__ import annotations

import contextlib

import pytest
import torch
from exportgen import tiny_model

from export.onnx_export import export_onnx
from export.preproc_graph import export_with_preprocessing
from export.single_channel import to_single_channel


@contextlib.contextmanager
def one_torch_thread():
    n = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        yield
    finally:
        torch.set_num_threads(n)


@pytest.fixture(autouse=True)
def _one_torch_thread():
    with one_torch_thread():
        yield


@pytest.fixture(scope="session")
def tiny1():
    """(single-channel model, meta) from a 3-channel tiny vgg11_bn width 0.125."""
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
