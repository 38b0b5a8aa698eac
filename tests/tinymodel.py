"""The tiny model of the shared ``tiny_pt`` / ``tiny_onnx`` fixtures (tests/conftest.py) and how it is exported.

A module of its own (not conftest) so tests can import it by name: several conftest modules exist.
"""

from __future__ import annotations

from pathlib import Path

from edge.meta import ModelMeta, SensorSpec, fov_intrinsics

TINY_H, TINY_W = 48, 64
TINY_SENSOR = SensorSpec(width=TINY_W, height=TINY_H, **dict(zip(("fx", "fy", "cx", "cy"),
                                                               fov_intrinsics(TINY_W, TINY_H, 62.0, 45.0))))
TINY_META = ModelMeta(encoder="vgg11", width=0.125, batch_norm=True, sensor=TINY_SENSOR)



def export_checkpoint(pt: Path, out: Path) -> Path:
    """Single-channel ONNX export of a checkpoint, as ``depthseg-export --single-channel`` does."""
    from edge.train.checkpoint import load_checkpoint
    from export.onnx_export import export_onnx
    from export.single_channel import to_single_channel

    model, meta, _ = load_checkpoint(pt)
    return export_onnx(*to_single_channel(model, meta), out)
