#!/usr/bin/env bash
# Reproduces every committed report of the shipped model (models/medium/) from its weights:
#   eval-val/    the validation choice set (8 sequences no medium model trains on): where the
#                rollout settings are chosen; network only and post-processed
#   eval/        the medium test split, 36 frames from the end of the ramp: the headline
#   eval-long/   the same test split over every moving frame (80), crumple at frame 36 and at the end
#   eval-default/ the default data set's test split
#   eval-large/  the large data set's test split (48 sequences: unseen outfits, spins, wind), 36
#                frames from the end of the ramp, per subset; Blender runs first when it is missing
#   stress/      600-frame stress runs on three test sequences, post-processed and network only
# Every baseline runs bare and with the model's post-processing. The medium validation and test
# sequences come from data/medium_choice (generate --splits val,test: the medium set's own files
# plus four more validation sequences); nothing here trains. Idempotent: a report that exists is
# kept (delete it to measure again). Usage: bash scripts/evaluate_shipped.sh [eval-val|eval|...]
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
bash scripts/setup.sh
bin=build/bin/layersnet
model=models/medium/model.h5
choice=data/medium_choice
only=${1:-all}

want() { [ "$only" = all ] || [ "$only" = "$1" ]; }
if [ "$only" != eval-default ] && [ "$only" != eval-large ]; then
  "$bin" generate --recipe generate/recipes/medium_choice.json --out "$choice" --splits val,test
fi
run_eval() {  # folder, then eval's options
  local out=models/medium/$1
  shift
  if [ -f "$out/eval.json" ]; then echo "evaluate_shipped: $out exists (kept)"; return; fi
  "$bin" eval --checkpoint "$model" --name LayersNet --constraints off,on --tether 0 --out "$out" "$@"
}
want eval-val && run_eval eval-val --dataset "$choice" --split val
want eval && run_eval eval --dataset "$choice" --split test
want eval-long && run_eval eval-long --dataset "$choice" --split test --frames 1000 --mark 36 --speed-frames 2
if want eval-default; then
  "$bin" generate --out data/default
  run_eval eval-default --dataset data/default --split test
fi
if want eval-large; then
  # One Blender thread per job, as the set was made: the cloth solver's sums depend on it.
  "$bin" generate --recipe generate/recipes/large.json --out data/large --splits test --jobs 2 --threads 1
  run_eval eval-large --dataset data/large --split test --frames 36
fi
if want stress; then
  mkdir -p models/medium/stress
  for id in 00040 00043 00046; do
    for mode in post network; do
      json=models/medium/stress/${id}_${mode}.json
      [ -f "$json" ] && continue
      set_args=()
      [ "$mode" = network ] && set_args=(--set eval.constraints=false)
      "$bin" stress --checkpoint "$model" --dataset "$choice" --sequence "$id" --tether 0 "${set_args[@]}" \
        --json "$json" > "models/medium/stress/${id}_${mode}.log" 2>&1 || true  # a failed bound is a result
    done
  done
fi
