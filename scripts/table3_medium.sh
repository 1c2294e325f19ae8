#!/usr/bin/env bash
# The paper's Table 3 (TIE, vanilla RIA, RIA + RET) on the medium data set, two training seeds
# each, with the shipped model's settings (configs/medium.toml) on a short schedule: EPOCHS
# epochs (default 2, about 15 min each on 2 idle cores). Every run is evaluated on the medium
# test split with the patch tether off, as the network alone (the paper's comparison) and with
# the cloth constraints, and the table is written to runs/table3/table3.md.
# Resumable: finished runs and evaluations are kept, an interrupted run resumes exactly.
# Usage: bash scripts/table3_medium.sh [BIN]   (BIN defaults to build/bin/layersnet)
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
bin=${1:-build/bin/layersnet}
epochs=${EPOCHS:-2}
data=data/medium
out=runs/table3
mkdir -p "$out"
"$bin" generate --recipe generate/recipes/medium.json --out "$data"
[ -f "$data/stats.h5" ] || "$bin" prepare "$data"

declare -A variant_keys=(
  [tie]="model.attention=tie model.rotation_equivalent=false"
  [vanilla]="model.attention=ria model.rotation_equivalent=false"
  [ria_ret]="model.attention=ria model.rotation_equivalent=true"
)
for seed in 0 1; do
  for variant in tie vanilla ria_ret; do
    run="$out/${variant}_seed$seed"
    # The table was measured with the official final-step gradient (train.bptt_steps 0).
    sets=(--set "train.seed=$seed" --set "train.epochs=$epochs" --set "train.lr_decay_epochs=[$epochs]" --set train.bptt_steps=0)
    for kv in ${variant_keys[$variant]}; do sets+=(--set "$kv"); done
    if [ ! -f "$run/metrics.jsonl" ] || ! grep -q '"event":"stop"' "$run/metrics.jsonl"; then
      if [ -f "$run/config.toml" ]; then
        "$bin" train --resume "$run" 2>&1 | tee -a "$run.log"
      else
        "$bin" train --config configs/medium.toml "${sets[@]}" --run "$run" 2>&1 | tee -a "$run.log"
      fi
    fi
    [ -f "$run/eval/eval.json" ] || "$bin" eval --checkpoint "$run/best.h5" --dataset "$data" --split test \
      --tether 0 --constraints off,on --name "$variant seed $seed" --out "$run/eval" 2>&1 | tee -a "$run.log"
  done
done
/usr/bin/python3 scripts/table3_summary.py "$out" > "$out/table3.md"
cat "$out/table3.md"
