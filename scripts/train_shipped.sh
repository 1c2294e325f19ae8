#!/usr/bin/env bash
# Reproduces the shipped model (models/medium/) from scratch: set-up, the medium data set,
# its statistics, training with configs/medium.toml, packing (weights + statistics + config,
# no optimizer state) and the evaluation on the medium test split. Idempotent and resumable:
# the data set resumes, an interrupted run resumes exactly, a finished one is kept.
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
bash scripts/setup.sh
bin=build/bin/layersnet
data=data/medium
run=runs/medium
out=models/medium

"$bin" generate --recipe generate/recipes/medium.json --out "$data"
/usr/bin/python3 generate/add_pins.py "$data"   # sets made before the files carried pin weights
[ -f "$data/stats.h5" ] || "$bin" prepare "$data"
mkdir -p "$(dirname "$run")"
if [ -f "$run/config.toml" ]; then
  "$bin" train --resume "$run" 2>&1 | tee -a "$run.log"
else
  "$bin" train --config configs/medium.toml --run "$run" 2>&1 | tee -a "$run.log"
fi
mkdir -p "$out"
"$bin" pack --checkpoint "$run/best.h5" --out "$out/model.h5"
cp "$run/config.toml" "$out/config.toml"
cp generate/recipes/medium.json "$out/recipe.json"
cp "$run/metrics.jsonl" "$out/metrics.jsonl"
cp "$run.log" "$out/train.log"
"$bin" eval --checkpoint "$out/model.h5" --dataset "$data" --split test --tether 0 --out "$out/eval"
