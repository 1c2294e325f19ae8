#!/usr/bin/env bash
# Reproduces the shipped model (models/medium/) from scratch: set-up, the medium data set,
# its statistics, training in two stages (configs/medium.toml, then configs/medium_projected.toml:
# fine-tuning on self-fed rollouts projected onto the cloth constraints), packing (weights +
# statistics + config, no optimizer state) and the evaluation on the medium test split.
# Idempotent and resumable: the data set resumes, an interrupted run resumes exactly, a
# finished one is kept.
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
bash scripts/setup.sh
bin=build/bin/layersnet
data=data/medium
run=runs/medium
tuned=runs/medium_projected
out=models/medium

"$bin" generate --recipe generate/recipes/medium.json --out "$data"
[ -f "$data/stats.h5" ] || "$bin" prepare "$data"
mkdir -p "$(dirname "$run")"
# train_stage CONFIG RUN [--set k=v ...]: starts the run, or resumes it exactly.
train_stage() {
  local config=$1 dir=$2
  shift 2
  if [ -f "$dir/config.toml" ]; then
    "$bin" train --resume "$dir" 2>&1 | tee -a "$dir.log"
  else
    "$bin" train --config "$config" --run "$dir" "$@" 2>&1 | tee -a "$dir.log"
  fi
}
train_stage configs/medium.toml "$run"
train_stage configs/medium_projected.toml "$tuned" --set "train.init_from=$run/best.h5"
mkdir -p "$out"
"$bin" pack --checkpoint "$tuned/best.h5" --out "$out/model.h5"
cp "$tuned/config.toml" "$out/config.toml"
cp generate/recipes/medium.json "$out/recipe.json"
cat "$run/metrics.jsonl" "$tuned/metrics.jsonl" > "$out/metrics.jsonl"
cat "$run.log" "$tuned.log" > "$out/train.log"
"$bin" eval --checkpoint "$out/model.h5" --dataset "$data" --split test --tether 0 --out "$out/eval"
