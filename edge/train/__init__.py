"""The torch part of depthseg: encoders, FCN-8s, checkpoints, the training set and loop, torch inference.

The only part of `edge` that imports torch (enforced by the import-linter contracts in
pyproject.toml). `export` builds on it; the runtime path (`edge.infer`, `edge.io`, `replay`)
never imports it. This ``__init__`` imports nothing, so ``import edge.train.predict`` does not
load torch until a checkpoint is actually opened.
"""
