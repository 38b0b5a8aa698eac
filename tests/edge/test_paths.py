"""The one path rule: inputs that would hang, outputs that would destroy an input or a special file."""

from __future__ import annotations

import os

import pytest

from edge.errors import ConfigError, DataError
from edge.io import atomic_write
from edge.io import paths as P


@pytest.fixture
def fifo(tmp_path):
    p = tmp_path / "pipe"
    os.mkfifo(p)
    return p


def test_fifo_input_refused_unless_asked(fifo):
    with pytest.raises(DataError, match="FIFO"):
        P.check_input_file(fifo, "model")
    assert P.check_input_file(fifo, "model", allow_special=True) == fifo


def test_missing_and_directory_inputs(tmp_path):
    with pytest.raises(DataError, match="no such file"):
        P.check_input_file(tmp_path / "nope.onnx", "model")
    with pytest.raises(DataError, match="directory"):
        P.check_input_file(tmp_path, "model")
    assert P.check_input_file(tmp_path, "data", allow_dir=True) == tmp_path


def test_output_equal_to_input_refused_through_other_spelling(tmp_path):
    model = tmp_path / "m.onnx"
    model.write_bytes(b"x")
    os.symlink(model, tmp_path / "link.onnx")
    for out in (model, tmp_path / "." / "m.onnx", tmp_path / "link.onnx"):
        with pytest.raises(ConfigError, match="overwrite the input `model`"):
            P.check_outputs({"out": out}, {"model": model})
    assert model.read_bytes() == b"x"


def test_output_inside_input_directory_refused(tmp_path):
    (tmp_path / "rec").mkdir()
    with pytest.raises(ConfigError, match="`data`"):
        P.check_outputs({"plot": tmp_path / "rec" / "new.png"}, {"data": [tmp_path / "rec"]})


def test_special_and_duplicate_outputs_refused(tmp_path, fifo):
    with pytest.raises(ConfigError, match="FIFO"):
        P.check_outputs({"out": fifo}, {})
    with pytest.raises(ConfigError, match="same file"):
        P.check_outputs({"out": tmp_path / "a", "plot": tmp_path / "a"}, {})
    P.check_outputs({"out": tmp_path / "a", "plot": tmp_path / "b", "json": None}, {"model": None})


def test_atomic_writer_never_replaces_a_fifo(fifo):
    with pytest.raises(DataError, match="not a regular file"):
        with atomic_write(fifo) as tmp:
            tmp.write_bytes(b"x")
    assert P.special_kind(fifo) == "FIFO"


def test_installed_package_is_protected(monkeypatch, tmp_path):
    root = tmp_path / "site-packages" / "edge"
    root.mkdir(parents=True)
    monkeypatch.setattr(P, "package_roots", lambda: [root])
    with pytest.raises(ConfigError, match="installed depthseg package"):
        P.check_outputs({"out": root / "models" / "default.onnx"}, {})
