"""`edge.errors.first_line`: the one rule for quoting a library's error in a one-line message."""

from __future__ import annotations

from edge.errors import first_line


def test_first_line_quotes_the_first_line_cut_to_the_limit():
    exc = RuntimeError("\n  onnx checker: node 3 is bad\nTraceback (most recent call last): ...")
    assert first_line(exc) == "onnx checker: node 3 is bad"
    assert first_line(exc, 12) == "onnx checker"


def test_an_empty_message_gives_the_class_name_instead_of_failing():
    assert first_line(ValueError()) == "ValueError"
    assert first_line(OSError("   ")) == "OSError"
