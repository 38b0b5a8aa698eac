#!/usr/bin/env bash
# Ablation of the v3 default's choices (README "Ablation"): input cues x width x simulated edge model.
# Each row: 6 epochs on the first 3,000 frames of a training set (same scenes: seed 1), then a
# single-channel export. Data: data/train4 (tools/ablation/train_v3_mix.json, the v3 training mix) and data/train_blur
# (the same config with the old blurred-edge fit, tools/ablation/train_blurred_edges.json):
#   .venv/bin/depthseg-sim --out data/train_blur --frames 3000 --seed 1 --workers 2 \
#       --config tools/ablation/train_blurred_edges.json
# data/train_v8 (issue 13, 8 views per settled scene, 375 scenes):
#   .venv/bin/depthseg-sim --out data/train_v8 --frames 3000 --seed 1 --workers 2 --shard-frames 80 \
#       --config tools/ablation/train_views8.json
# Measured: ~8 min a row on this 2-core machine when nothing else runs.
#   bash tools/ablation/run_ablation.sh [ROW ...]      # default: all rows
set -euo pipefail
cd "$(dirname "$0")/../.."
BIN=.venv/bin
COMMON="--limit 3000 --encoder vgg11 --batch-norm --in-channels 3 --standardize robust --extra-skip --epochs 6 \
 --batch-size 16 --lr 1e-3 --lr-schedule cosine --patience 6 --threads 2"
row() {  # name data width cues [seed [further depthseg-train flags]]
  local name=$1 data=$2 width=$3 cues=$4 seed=${5:-0} flags=${6:-}
  local extra="$flags"; [ "$cues" != none ] && extra="--cues $cues $flags"
  [ -f "runs/ablation/$name/best.pt" ] || $BIN/depthseg-train --data "$data" --out "runs/ablation/$name" --width "$width" $extra $COMMON --seed "$seed"
  $BIN/depthseg-export --model "runs/ablation/$name/best.pt" --single-channel --out "runs/ablation/$name/model.onnx" --data "$data"
}
ROWS=${*:-"zh_w125 z_w125 zh_w125_blur zh_w25"}
for r in $ROWS; do
  case $r in
    zh_w125) row zh_w125 data/train4 0.125 height ;;
    z_w125) row z_w125 data/train4 0.125 none ;;
    zh_w125_blur) row zh_w125_blur data/train_blur 0.125 height ;;
    zh_w25) row zh_w25 data/train4 0.25 height ;;
    zh_w125_v8) row zh_w125_v8 data/train_v8 0.125 height ;;  # issue 13: 8 camera views per settled scene
    # the steepness cue (1 - cos of the normal's angle to the optical axis, edge.cues.steepness_cue)
    # against height alone, on the shipped recipe's data (data/train_v19, tools/train_default.sh), two seeds each
    zh_v19) row zh_v19 data/train_v19 0.125 height ;;
    zh_v19_s1) row zh_v19_s1 data/train_v19 0.125 height 1 ;;
    zhs_v19) row zhs_v19 data/train_v19 0.125 height,steepness ;;
    zhs_v19_s1) row zhs_v19_s1 data/train_v19 0.125 height,steepness 1 ;;
    zs_v19) row zs_v19 data/train_v19 0.125 steepness ;;
    z_v19) row z_v19 data/train_v19 0.125 none ;;
    # boundary-weighted BCE (--boundary-weight: pixels within 2 px of a label outline weigh 1 + W)
    # against zh_v19 / zh_v19_s1 above, same data and seeds
    zhb2_v19) row zhb2_v19 data/train_v19 0.125 height 0 "--boundary-weight 2" ;;
    zhb2_v19_s1) row zhb2_v19_s1 data/train_v19 0.125 height 1 "--boundary-weight 2" ;;
    zhb5_v19) row zhb5_v19 data/train_v19 0.125 height 0 "--boundary-weight 5" ;;
    *) echo "unknown row $r" >&2; exit 2 ;;
  esac
done
