"""Per-frame intrinsics between the datasheet pinhole and the real pico flexx calibration."""

from __future__ import annotations

import numpy as np
import pytest

from edge.errors import ConfigError
from sim.generate import REAL_PICO_FLEXX_K, SimConfig, generate_frame


def test_default_config_keeps_the_datasheet_camera() -> None:
    cfg = SimConfig()
    assert cfg.camera_for(np.random.default_rng(0)) == cfg.camera
    assert "intrinsics_steps" not in cfg.to_dict()  # digest of existing outputs unchanged


def test_steps_span_datasheet_to_real_calibration() -> None:
    cfg = SimConfig.from_dict({"intrinsics_steps": 3})
    rng = np.random.default_rng(0)
    seen = {cfg.camera_for(rng).intrinsics for _ in range(60)}
    a, b = np.array(cfg.camera.intrinsics), np.array(REAL_PICO_FLEXX_K)
    expected = {tuple((a + t * (b - a)).round(4).tolist()) for t in (0.0, 0.5, 1.0)}
    assert seen == expected


def test_frames_carry_their_drawn_intrinsics_deterministically() -> None:
    cfg = SimConfig.from_dict({"intrinsics_steps": 8, "scene": {"n_objects": [0, 0]}})
    ks = [generate_frame(i, 3, cfg).intrinsics for i in range(6)]
    assert len(set(ks)) > 1
    assert ks == [generate_frame(i, 3, cfg).intrinsics for i in range(6)]


@pytest.mark.parametrize(
    "bad", [{"intrinsics_steps": -1}, {"intrinsics_steps": True}, {"intrinsics_steps": 2.5},
            {"intrinsics_steps": 4, "intrinsics_to": [1, 2, 3]}, {"intrinsics_to": [200, "x", 100, 80]}],
)
def test_bad_intrinsics_settings_are_config_errors(bad: dict) -> None:
    with pytest.raises(ConfigError):
        SimConfig.from_dict(bad)
