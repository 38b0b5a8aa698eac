#!/usr/bin/env bash
# Whole-frame latency of the edge path at git revision REV against the working tree, interleaved:
# `depthseg-bench` of the same models on the same frames, run alternately with REV's code (a
# temporary `git worktree`) and this checkout's, ROUNDS times each. Why: a change of the numpy
# pre- or postprocessing is timed where it matters, the whole frame, and the machines of these
# sessions drift up to 2x in minutes, so only alternating runs compare (report the ratio beside
# the absolute numbers). The models are this checkout's files for both sides.
#
#   bash tools/bench_against.sh 4901867                     # default and fast option, 4 rounds
#   ROUNDS=2 MODELS="edge/models/default.onnx" bash tools/bench_against.sh HEAD~1
set -euo pipefail
cd "$(dirname "$0")/.."
REV=${1:?usage: bash tools/bench_against.sh REV}
ROUNDS=${ROUNDS:-4}
MODELS=${MODELS:-"edge/models/default.onnx edge/models/fast.onnx"}
RUNS=${RUNS:-200}
DATA=${DATA:-data/test_default}
HERE=$(pwd)
PY="$HERE/.venv/bin/python"
OLD=$(mktemp -d)
trap 'git worktree remove --force "$OLD" >/dev/null 2>&1 || rm -rf "$OLD"' EXIT
git worktree add --detach -f "$OLD" "$REV" >/dev/null 2>&1
models=()
for m in $MODELS; do models+=("$HERE/$m"); done
for i in $(seq 1 "$ROUNDS"); do
  for side in "$REV:$OLD" "working tree:$HERE"; do
    name=${side%%:*}; dir=${side#*:}
    echo "== round $i, $name"
    # run from the checkout's folder, so its own edge/ and export/ packages are the ones imported
    (cd "$dir" && "$PY" -c "import sys; from export.bench_cli import main; sys.exit(main(sys.argv[1:]))" \
      --model "${models[@]}" --threads 2 --data "$HERE/$DATA" --runs "$RUNS" | grep -E "^(model|[a-z_0-9.-]+ +(fp32|int8)) ")
  done
done
