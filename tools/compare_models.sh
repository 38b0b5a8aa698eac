#!/usr/bin/env bash
# Held-out simulated IoU (mean over frames, %) of several models side by side: the numbers a
# candidate default is chosen by (never the shared BlenSor or real frames).
#   bash tools/compare_models.sh edge/models/default.onnx runs/views4/model.onnx
set -euo pipefail
cd "$(dirname "$0")/.."
SETS=${SETS:-"data/test_default data/test_crisp data/test_blurred data/test_thin data/test_table_edge data/test_tilted data/test_curved data/test_tray data/test_stacked data/test_default_geo10.mcap"}
printf "%-32s" "data"; for m in "$@"; do printf " %28s" "$(basename "$(dirname "$m")")/$(basename "$m")"; done; echo
for s in $SETS; do
  printf "%-32s" "$(basename "$s")"
  for m in "$@"; do
    v=$(.venv/bin/depthseg-eval --model "$m" --data "$s" --json | .venv/bin/python -c \
      'import json,sys; r=json.load(sys.stdin); print("%.2f" % (100*r["iou"]))' 2>/dev/null || echo "?")
    printf " %28s" "$v"
  done; echo
done
