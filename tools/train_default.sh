#!/usr/bin/env bash
# Recipe of the shipped default model (edge/models/default.pt and default.onnx), v20 (candidate B):
# v19d's recipe with --boundary-weight 2 (pixels within 2 px of a label outline weigh 3x in the BCE;
# BENCHMARKS.md "candidate B, results").
#
#   bash tools/train_default.sh            # v19d's recipe took 54-83 min on a 2-core AMD EPYC, by the day: 54.2 and
#                                          # 60.7 min on 2026-12-02 (v19, v19c), 83.0 min on 2026-12-03 (v19d, a ~1.5x
#                                          # slower machine); v20's (this script) 80.3 min from nothing on 2026-12-03,
#                                          # reproducing the shipped weights bit for bit, and 77.9 min on 2026-12-07 (bit
#                                          # for bit again, with the loss's band by box sums); BENCHMARKS.md "candidate v19",
#                                          # "candidate v19d, results", "v20's recipe from nothing, results",
#                                          # "v20's recipe from nothing on 2026-12-07, results"
#   FRAMES=24000 bash tools/train_default.sh   # the previous default v12's data volume (~52-60 min)
#
# 1. simulate 32,000 labelled frames (seed 1; 4 camera views of each of 8,000 settled scenes, which
#    makes ~100 frames/s with 2 workers) with the pico flexx sensor model, wider domain
#    randomisation and the scene families where a plane fit fails (tools/default_sim_config.json:
#    noise level x0.7-3.5, 30 % white-noise frames as BlenSor's, dead-corner cone 31.5-38 deg, edges
#    from crisp to the real sensor's (PSF 0-0.5 px, 3 % of flying pixels
#    left by the filter), intrinsics from the datasheet to the real
#    calibration, 20 % thin objects 3-8 mm, 20 % frames with a table edge, camera tilt +-15 deg,
#    5 % long objects: handles, rods and sticks 12-30 cm lying across the scene),
# 2. train a compact FCN-8s (VGG11 encoder with batch norm, width x0.125, extra pool2/pool1 skips
#    and the full-resolution conv1 skip,
#    depth replicated to 3 channels as in the paper plus a height-above-dominant-plane channel,
#    robust standardisation) from scratch with an 85/10/5 split and early stopping (a split of
#    frames, --split-unit frame, as for every default so far, so that this script still makes the
#    shipped model; depthseg-train's own default deals whole scenes), validating
#    and keeping an exponential moving average of the weights (--ema 0.999, ~1,000 steps),
# 3. install the best weights as the default and export the single-channel ONNX model (first-conv
#    weights summed over the three depth channels; the height channel's weights kept).
# Since 2026-12-02 depthseg-train keeps weights and inputs channels-last (--memory-format
# channels_last, its default): the same arithmetic in another order, 2.2-2.3x faster steps on an
# AMD EPYC, 1.4-1.6x on an Intel Xeon (BENCHMARKS.md, "a training step in channels-last layout").
# Since 2026-12-02 it also preprocesses every frame once before the first epoch (--preprocess once,
# its default; epochs x0.87-0.96, BENCHMARKS.md "preprocessing once"), so the flips turn the
# preprocessed frame; candidate v19 (32,000 frames) showed this keeps the accuracy.
# The previous default v12 (FRAMES=24000) was trained in the old NCHW layout, preprocessed per batch;
# FLAGS="--memory-format contiguous --preprocess per-batch" reruns exactly that (1.5-2x as long).
# On a CPU with AMX (Intel Sapphire Rapids and later: `grep -c amx_bf16 /proc/cpuinfo`), use
#   FLAGS="--precision bf16" bash tools/train_default.sh
# bfloat16 autocast of the forward pass, ~1.4x faster steps there: 55.6 min for the whole recipe
# from nothing on 2026-12-02 (candidate v17, held-out mean 97.18 against v12's 97.15, i.e. the
# same model within seed noise), where float32 would take ~72 min (estimated from the step
# ratio); no faster on the AMD EPYC.
# The test set used for the README numbers is simulated separately from seed 2 (never trained on).
set -euo pipefail
cd "$(dirname "$0")/.."
BIN=.venv/bin
DATA=${DATA:-data/train_v19}
RUN=${RUN:-runs/v19}
FRAMES=${FRAMES:-32000}
EPOCHS=${EPOCHS:-11}
MINUTES=${MINUTES:-}  # a wall-clock cap (minutes) for trials; unset, all epochs run, so the model is the same on a slow machine
CONFIG=${CONFIG:-tools/default_sim_config.json}
INSTALL=${INSTALL:-1}  # 0: train a candidate in $RUN without installing it as the default
FLAGS=${FLAGS:-}  # further depthseg-train flags for a candidate, split on spaces (v8 was FLAGS=--full-skip before it joined the recipe)
start=$(date +%s)
$BIN/depthseg-sim --out "$DATA" --frames "$FRAMES" --seed 1 --workers 2 --config "$CONFIG"
$BIN/depthseg-train --data "$DATA" --out "$RUN" --encoder vgg11 --batch-norm --width 0.125 \
  --in-channels 3 --cues height --standardize robust --extra-skip --full-skip --split 0.85,0.1,0.05 --split-unit frame --epochs "$EPOCHS" --batch-size 16 --lr 1e-3 --lr-schedule cosine \
  --patience 6 ${MINUTES:+--max-minutes "$MINUTES"} --seed 0 --threads 2 --ema 0.999 --boundary-weight 2 $FLAGS
if [ "$INSTALL" = 1 ]; then
  cp "$RUN/best.pt" edge/models/default.pt
  $BIN/depthseg-export --model edge/models/default.pt --single-channel --out edge/models/default.onnx --data "$DATA"
else
  $BIN/depthseg-export --model "$RUN/best.pt" --single-channel --out "$RUN/model.onnx" --data "$DATA"
fi
end=$(date +%s)
echo "train_default: done in $(( (end - start) / 60 )) min"
