"""edge.values: the number and quoting rules shared by sim config and model-metadata checks."""

from __future__ import annotations

import numpy as np

from edge.values import is_finite, is_number, show


def test_show_cuts_long_values_to_one_short_line():
    assert show("x" * 10) == repr("x" * 10)
    cut = show("x" * 1_000_000)
    assert len(cut) == 60 and cut.endswith("...")


def test_bools_and_strings_are_not_numbers_numpy_scalars_are():
    assert is_number(3) and is_number(2.5) and is_number(np.float32(1)) and is_number(np.int64(7))
    assert not any(is_number(v) for v in (True, np.bool_(False), "3", None, [1]))


def test_finite_refuses_nan_infinity_and_ints_beyond_a_float():
    assert is_finite(1e300) and is_finite(10**300)
    assert not any(is_finite(v) for v in (float("nan"), float("inf"), 10**400))
