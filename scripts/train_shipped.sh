#!/usr/bin/env bash
# Reproduces a shipped model from scratch: set-up, its data, training, packing (weights +
# statistics + config, no optimizer state) and its evaluations. Idempotent and resumable: the data
# sets resume, an interrupted run resumes exactly, a finished one is kept; scripts/evaluate_shipped.sh
# then makes its reports (one that exists is kept: delete it to measure again).
#
#   bash scripts/train_shipped.sh [medium|large]     (default: medium)
#
# medium: models/medium/. The medium data set and its statistics, the medium_plus data set grown
#   from it, configs/medium_plus.toml (which normalises with data/medium's statistics).
# large:  models/large/, one stage from scratch. The large recipe's validation and test splits and
#   the first LARGE_TRAIN (112) sequences of its training split, frozen so that the run's data and
#   statistics do not change while the split grows; configs/large.toml with LARGE_SEED (0) on every
#   core (runs/large; the same bits as on one thread, train/README.md).
#   Blender makes those 184 sequences in about 3 hours on 2 cores (the whole recipe, 792, in about
#   15); training takes 40-50 minutes on one core, 1.6-1.7x less on two.
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
name=${1:-medium}
case "$name" in medium|large) ;; *) echo "train_shipped: unknown model '$name' (medium or large)" >&2; exit 2 ;; esac
bash scripts/setup.sh
bin=build/bin/layersnet
out=models/$name
if [ "$name" = medium ]; then
  medium=data/medium
  data=data/medium_plus
  run=runs/medium_plus
  config=(--config configs/medium_plus.toml)
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
  recipe=generate/recipes/medium_plus.json
else
  n_train=${LARGE_TRAIN:-112}
  seed=${LARGE_SEED:-0}
  data=runs/large$n_train
  run=runs/large
  config=(--config configs/large.toml --set data.dataset="$data" --set data.cache_sequences="$n_train"
          --set train.seed="$seed")
  # One Blender thread per job, as the set was made: the cloth solver's sums depend on it.
  gen() { "$bin" generate --recipe generate/recipes/large.json --out data/large --jobs 2 --threads 1 "$@"; }
  gen --splits val,test
  gen --splits train --train-limit "$n_train"
  [ -f "$data/dataset.json" ] || /usr/bin/python3 scripts/freeze_train_split.py data/large "$data" --max-train "$n_train"
  [ -f "$data/stats.h5" ] || "$bin" prepare "$data"
  recipe=generate/recipes/large.json
fi

train_run() {  # run directory, then train's options for a new run; an existing run resumes (exactly)
  local dir=$1
  shift
  mkdir -p "$(dirname "$dir")"
  if [ -f "$dir/config.toml" ]; then
    "$bin" train --resume "$dir" 2>&1 | tee -a "$dir.log"
  else
    "$bin" train "$@" --run "$dir" 2>&1 | tee -a "$dir.log"
  fi
}
train_run "$run" "${config[@]}"
mkdir -p "$out"
"$bin" pack --checkpoint "$run/best.h5" --out "$out/model.h5"   # again each time: the run may be newer
cp "$run/config.toml" "$out/config.toml"
cp "$recipe" "$out/recipe.json"
gzip -9 -n -c "$run/metrics.jsonl" > "$out/metrics.jsonl.gz"   # the training record, a fifth the size

bash scripts/evaluate_shipped.sh "$name" all
