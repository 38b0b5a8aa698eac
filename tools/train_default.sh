#!/usr/bin/env bash
# Recipe of the shipped default model (edge/models/default.pt and default.onnx).
#
#   bash tools/train_default.sh            # measured: see BENCHMARKS.md ("Training the default")
#
# 1. simulate 6,000 labelled frames (seed 1) with the pico flexx sensor model and wider domain
#    randomisation (tools/default_sim_config.json: noise level x0.7-3.5, dead-corner cone 31.5-38 deg,
#    so some frames have no dead corners, as BlenSor's), 2. train a compact FCN-8s (VGG11 encoder with
# batch norm, width x0.125, depth replicated to 3 channels as in the paper) from scratch with the
# paper's 70/20/10 split and early stopping, 3. install the best weights as the default and export
# the single-channel ONNX model (first-conv weights summed over the input channels).
# The test set used for the README numbers is simulated separately from seed 2 (never trained on).
set -euo pipefail
cd "$(dirname "$0")/.."
BIN=.venv/bin
DATA=${DATA:-data/train}
RUN=${RUN:-runs/default}
FRAMES=${FRAMES:-6000}
EPOCHS=${EPOCHS:-20}
MINUTES=${MINUTES:-70}
start=$(date +%s)
$BIN/depthseg-sim --out "$DATA" --frames "$FRAMES" --seed 1 --workers 2 --config tools/default_sim_config.json
$BIN/depthseg-train --data "$DATA" --out "$RUN" --encoder vgg11 --batch-norm --width 0.125 \
  --in-channels 3 --epochs "$EPOCHS" --batch-size 16 --lr 1e-3 --lr-schedule cosine \
  --patience 6 --max-minutes "$MINUTES" --seed 0 --threads 2
cp "$RUN/best.pt" edge/models/default.pt
$BIN/depthseg-export --model edge/models/default.pt --single-channel --out edge/models/default.onnx --data "$DATA"
end=$(date +%s)
echo "train_default: done in $(( (end - start) / 60 )) min"
