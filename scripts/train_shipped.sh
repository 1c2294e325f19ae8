#!/usr/bin/env bash
# Reproduces the shipped model (models/medium/) from scratch: set-up, the medium data set and its
# statistics, the medium_plus data set grown from it, training with configs/medium_plus.toml
# (which normalises with data/medium's statistics), packing (weights + statistics + config, no
# optimizer state) and the evaluation on the medium test split. Idempotent and resumable: the
# data sets resume, an interrupted run resumes exactly, a finished one is kept.
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
bash scripts/setup.sh
bin=build/bin/layersnet
medium=data/medium
data=data/medium_plus
run=runs/medium_plus
out=models/medium

"$bin" generate --recipe generate/recipes/medium.json --out "$medium"
/usr/bin/python3 generate/add_pins.py "$medium"   # sets made before the files carried pin weights
[ -f "$medium/stats.h5" ] || "$bin" prepare "$medium"
# medium_plus keeps the medium files at their indices: copied here, checked and kept by generate.
mkdir -p "$data/reports"
for f in "$medium"/0*.h5 "$medium"/reports/*; do
  dest="$data/${f#"$medium"/}"
  [ -e "$dest" ] || cp "$f" "$dest"
done
"$bin" generate --recipe generate/recipes/medium_plus.json --out "$data"
[ -f "$data/stats.h5" ] || "$bin" prepare "$data"
mkdir -p "$(dirname "$run")"
if [ -f "$run/config.toml" ]; then
  "$bin" train --resume "$run" 2>&1 | tee -a "$run.log"
else
  "$bin" train --config configs/medium_plus.toml --run "$run" 2>&1 | tee -a "$run.log"
fi
mkdir -p "$out"
"$bin" pack --checkpoint "$run/best.h5" --out "$out/model.h5"
cp "$run/config.toml" "$out/config.toml"
cp generate/recipes/medium_plus.json "$out/recipe.json"
cp "$run/metrics.jsonl" "$out/metrics.jsonl"
cp "$run.log" "$out/train.log"
"$bin" eval --checkpoint "$out/model.h5" --name "shipped (medium)" --dataset "$medium" --split test --constraints off,on \
  --tether 0 --out "$out/eval"
