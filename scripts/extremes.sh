#!/usr/bin/env bash
# Stability at the extremes, full version (the short version is
# tests/eval/test_extremes.cpp in CI):
#   1. `layersnet stress` on the default model, on every test and validation sequence of the
#      default data: 600-frame rollouts at wind 0, 400, 2000 and with the body at 5x speed
#      (finite, every vertex within its distance bound, every frame's edge-strain p99 under
#      the limit, eval/stress.h; the checkpoint's eval.patch_tether applies, 0 = off by
#      default, eval/tether.h), and float32 vs float64 over 100
#      frames on the first (divergence below the model's own error);
#   2. training at 10x the default learning rate on the default data for a short budget:
#      it must either finish or be stopped by the non-finite guard (exit 1 with a message
#      naming the fix) — never a signal — and every checkpoint it leaves must load with
#      finite weights.
# Needs the default run (runs/default/best.h5). Knobs: LAYERSNET_BIN (default
# build/bin/layersnet), EXTREMES_OUT (default /tmp/layersnet_extremes), EXTREMES_FRAMES (600),
# EXTREMES_LR_STEPS (200 updates of 4 samples; about 7 min at 2 samples/s).
# Exit status: 0 when both parts pass, 1 otherwise.
set -uo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
bin=${LAYERSNET_BIN:-build/bin/layersnet}
out=${EXTREMES_OUT:-/tmp/layersnet_extremes}
frames=${EXTREMES_FRAMES:-600}
lr_steps=${EXTREMES_LR_STEPS:-200}
checkpoint=runs/default/best.h5
python=/usr/bin/python3

if [ ! -x "$bin" ]; then
  echo "extremes: $bin not found; build first: bash scripts/setup.sh (or set LAYERSNET_BIN)" >&2
  exit 2
fi
if ! "$bin" --help 2>/dev/null | grep -qE "^  stress( |$)"; then
  echo "extremes: $bin has no 'stress' subcommand; rebuild it: cmake --build build -j2 --target layersnet" >&2
  exit 2
fi
if [ ! -f "$checkpoint" ] || [ ! -f data/default/stats.h5 ]; then
  echo "extremes: needs the default model and data ($checkpoint, data/default/stats.h5);" >&2
  echo "          run the main job first: bash scripts/run_default.sh" >&2
  exit 2
fi
mkdir -p "$out"
status=0

# The test and validation sequences: none of them was trained on.
sequences=$("$python" -c 'import json,sys; s=json.load(open(sys.argv[1]))["splits"]; print(" ".join(s.get("test",[])+s.get("val",[])))' data/default/dataset.json)
echo "== 1. layersnet stress on $sequences ($frames frames, winds 0/400/2000, speed 5x; float32 vs float64 over 100 frames on the first)"
precision=100
for id in $sequences; do
  "$bin" stress --checkpoint "$checkpoint" --dataset data/default --sequence "$id" --frames "$frames" \
    --winds 0,400,2000 --speed 5 --precision-frames "$precision" --json "$out/stress_$id.json"
  rc=$?
  echo "stress $id exit code: $rc"
  [ "$rc" -eq 0 ] || status=1
  precision=0
  echo
done
echo
echo "== 2. training at 10x the default learning rate (0.01), $lr_steps updates"
run="$out/lr10x"
rm -rf "$run"
"$bin" train --config configs/default.toml --set train.learning_rate=0.01 --set "train.max_steps=$lr_steps" \
  --set train.checkpoint_every=50 --run "$run" > "$out/lr10x.log" 2>&1
rc=$?
tail -n 5 "$out/lr10x.log"
if [ "$rc" -eq 0 ]; then
  echo "training finished (exit 0)"
elif [ "$rc" -eq 1 ] && grep -q "learning_rate" "$out/lr10x.log"; then
  echo "training stopped by the non-finite guard (exit 1, message names the fix)"
else
  echo "training FAILED: exit code $rc (a signal or an unexpected error); see $out/lr10x.log"
  status=1
fi
# Every checkpoint left: h5py reads every weight and finds it finite; layersnet loads the newest.
shopt -s nullglob
files=("$run"/checkpoints/step_*.h5 "$run"/best.h5)
if [ "${#files[@]}" -eq 0 ]; then
  echo "no checkpoint was written"
  [ "$rc" -eq 0 ] && status=1
else
  if ! "$python" - "${files[@]}" <<'EOF'
import sys, h5py, numpy as np
bad = 0
for path in sys.argv[1:]:
    with h5py.File(path, "r") as f:
        n = 0
        for name, w in f["weights"].items():
            n += w.size
            if not np.all(np.isfinite(w[...])):
                print(f"{path}: /weights/{name} holds non-finite values"); bad += 1
        print(f"{path}: {len(f['weights'])} tensors, {n} weights, step {f['state'].attrs['global_step']}, finite")
sys.exit(1 if bad else 0)
EOF
  then status=1; fi
  newest=$(ls "$run"/checkpoints/step_*.h5 2>/dev/null | tail -n 1)
  if [ -n "$newest" ]; then
    if "$bin" stress --checkpoint "$newest" --dataset data/default --frames 6 --winds 0 --speed 0 \
         --precision-frames 0 > "$out/lr10x_load.log" 2>&1 || grep -q "^| wind 0 |" "$out/lr10x_load.log"; then
      echo "$newest loads and rolls out (layersnet stress, 3 frames)"
    else
      echo "$newest does NOT load: see $out/lr10x_load.log"; status=1
    fi
  fi
fi
echo
echo "extremes: $([ "$status" -eq 0 ] && echo passed || echo FAILED); reports in $out"
exit "$status"
