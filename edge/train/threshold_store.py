"""Write a tuned decision boundary (and the policy that chose it) into a model file.

Why in the file: eval, replay and bench read the threshold from the model's metadata, so a
tuned model carries its boundary wherever it is copied; no flag to forget.

- ONNX: ``metadata_props`` are rewritten with the ``onnx`` package: the full `ModelMeta` JSON
  under ``depthseg`` plus the flat keys from `ModelMeta.onnx_props` (``threshold``,
  ``threshold_policy``, ...). Other keys (e.g. quantisation notes from export) are kept.
- Checkpoint (``.pt``/``.pth``): ``blob["meta"]`` is updated through `edge.train.checkpoint`; torch is
  imported only for this branch.

Without ``out`` the model is rewritten in place after copying it to ``<model>.bak``; every
file appears under its final name only when complete (temp file + rename).
"""

from __future__ import annotations

import shutil
from pathlib import Path

from edge.errors import ModelError
from edge.io import atomic_write
from edge.meta import META_KEY, ModelMeta

__all__ = ["store_threshold", "read_meta", "backup_path"]

ONNX_SUFFIXES = (".onnx",)
TORCH_SUFFIXES = (".pt", ".pth")


def backup_path(model: Path) -> Path:
    return model.with_name(model.name + ".bak")


def _kind(path: Path) -> str:
    s = path.suffix.lower()
    if s in ONNX_SUFFIXES:
        return "onnx"
    if s in TORCH_SUFFIXES:
        return "pt"
    raise ModelError(f"{path}: unknown model type '{s or '(no suffix)'}'; expected .onnx, .pt or .pth")


def _load_onnx(path: Path):
    import onnx

    try:
        return onnx.load(str(path))
    except Exception as exc:  # noqa: BLE001 - any parse failure means a corrupt or foreign file
        raise ModelError(f"{path}: not a readable ONNX model ({type(exc).__name__}); re-export it with depthseg-export") from None


def read_meta(path: str | Path) -> ModelMeta:
    """The `ModelMeta` stored in an ONNX file or a checkpoint."""
    p = Path(path)
    if not p.is_file():
        raise ModelError(f"{p}: no such model file")
    if _kind(p) == "onnx":
        model = _load_onnx(p)
        return _onnx_meta(p, {e.key: e.value for e in model.metadata_props})
    from edge.train.checkpoint import checkpoint_meta

    return checkpoint_meta(p)


def _onnx_meta(path: Path, props: dict[str, str]) -> ModelMeta:
    try:
        return ModelMeta.from_onnx_props(props)
    except ModelError as exc:
        raise ModelError(f"{path}: {exc}") from None


def _write_onnx(src: Path, dst: Path, threshold: float, policy: str) -> ModelMeta:
    import onnx

    model = _load_onnx(src)
    props = {e.key: e.value for e in model.metadata_props}
    if META_KEY not in props:
        raise ModelError(f"{src}: ONNX model has no '{META_KEY}' metadata; export it with depthseg-export first")
    meta = _onnx_meta(src, props).with_(threshold=float(threshold), threshold_policy=policy)
    props.update(meta.onnx_props())
    del model.metadata_props[:]
    for k in props:  # keep the original key order, new keys last
        model.metadata_props.append(onnx.StringStringEntryProto(key=k, value=props[k]))
    # External weights (if any) were loaded above and are written back inline: a model that
    # fits in one protobuf (< 2 GB; ours is ~0.5 GB at full width) stays one self-contained file.
    with atomic_write(dst) as tmp:
        onnx.save(model, str(tmp))
    return meta


def _write_checkpoint(src: Path, dst: Path, threshold: float, policy: str) -> ModelMeta:
    import torch

    from edge.train.checkpoint import checkpoint_meta, read_checkpoint

    blob = read_checkpoint(src)
    meta = checkpoint_meta(src, blob).with_(threshold=float(threshold), threshold_policy=policy)
    blob["meta"] = meta.to_dict()
    with atomic_write(dst) as tmp:
        torch.save(blob, tmp)
    return meta


def _copy_atomic(src: Path, dst: Path) -> None:
    with atomic_write(dst) as tmp:
        shutil.copy2(src, tmp)


def store_threshold(
    model: str | Path, threshold: float, policy: str, out: str | Path | None = None
) -> tuple[Path, Path | None, ModelMeta]:
    """Write ``threshold`` (a probability in (0, 1)) and ``policy`` into ``model``.

    Returns (written file, backup file or None, the new metadata). ``out`` writes a new file
    (same type as ``model``); otherwise ``model`` is first copied to ``<model>.bak``.
    """
    src = Path(model)
    if not src.is_file():
        raise ModelError(f"{src}: no such model file")
    kind = _kind(src)
    if not 0.0 < float(threshold) < 1.0:
        raise ModelError(f"threshold must lie in (0, 1), got {threshold}")
    dst = Path(out) if out is not None else src
    if out is not None:
        if dst.is_dir():
            raise ModelError(f"`out` {dst}: is a directory, expected a model file name")
        if _kind(dst) != kind:
            raise ModelError(f"`out` {dst}: must have the model's type ({src.suffix}), got '{dst.suffix}'")
        if not dst.parent.exists():
            raise ModelError(f"`out` {dst}: directory {dst.parent} does not exist")
    backup = None
    if dst.resolve() == src.resolve():
        backup = backup_path(src)
        _copy_atomic(src, backup)
    write = _write_onnx if kind == "onnx" else _write_checkpoint
    meta = write(src, dst, float(threshold), str(policy))
    return dst, backup, meta
