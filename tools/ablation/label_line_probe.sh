#!/usr/bin/env bash
# Probe (issue 9): what does training on labels with a 10 mm line (the real capture's geometric
# rule: object parts lower than 10 mm above the table are table; thin objects stay object whole)
# do to the held-out sets, against the same recipe on the simulator's own labels?
# Both arms: the same 8,000 frames (seed 1, v20's recipe's config, tools/ablation/train_v20.json; the line changes labels
# only, so the depth frames are identical), the shipped recipe's flags, 8 epochs.
#   bash tools/ablation/label_line_probe.sh           # ~40 min on a 2-core machine (both arms); FRAMES=6000 EPOCHS=6: ~20 min
# then: .venv/bin/python tools/ablation/eval_ablation.py --candidates runs/probe_rays/model.onnx runs/probe_line10/model.onnx
set -euo pipefail
cd "$(dirname "$0")/../.."
BIN=.venv/bin
FRAMES=${FRAMES:-8000}
EPOCHS=${EPOCHS:-8}
$BIN/depthseg-sim --out data/probe_rays --frames "$FRAMES" --seed 1 --workers 2 --config tools/ablation/train_v20.json
$BIN/depthseg-sim --out data/probe_line10 --frames "$FRAMES" --seed 1 --workers 2 --config tools/ablation/train_label10.json
for arm in rays line10; do
  [ -f "runs/probe_$arm/best.pt" ] || $BIN/depthseg-train --data "data/probe_$arm" --out "runs/probe_$arm" \
    --encoder vgg11 --batch-norm --width 0.125 --in-channels 3 --cues height --standardize robust --extra-skip \
    --full-skip --split 0.85,0.1,0.05 --split-unit frame --epochs "$EPOCHS" --batch-size 16 --lr 1e-3 \
    --lr-schedule cosine --patience 6 --seed 0 --threads 2 --ema 0.999
  $BIN/depthseg-export --model "runs/probe_$arm/best.pt" --single-channel --out "runs/probe_$arm/model.onnx" \
    --data "data/probe_$arm"
done
