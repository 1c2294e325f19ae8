#!/usr/bin/env bash
# The main job on the embedded default: install what is missing, build, make (or find)
# the default data set, prepare its statistics, and run every stage the program has.
# Idempotent: existing data, statistics and runs are reused.
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
bash scripts/setup.sh
bin=build/bin/layersnet
data=data/default

has() { "$bin" --help | grep -qE "^  $1( |$)"; }

if has generate; then
  "$bin" generate --out "$data"   # resumes: existing valid sequences are kept
  # Sequences generated before the files carried pin weights get them (a no-op otherwise).
  /usr/bin/python3 generate/add_pins.py "$data"
fi
if [ -f "$data/dataset.json" ]; then
  has prepare && "$bin" prepare "$data"
  has inspect && "$bin" inspect "$data" --brief --config configs/default.toml
fi
if has train && [ -f "$data/stats.h5" ]; then
  if [ -f runs/default/config.toml ]; then
    "$bin" train --resume runs/default   # finishes an interrupted run; a finished one is kept
  else
    "$bin" train --config configs/default.toml --run runs/default
  fi
fi
if has eval && [ -d runs/default ]; then
  # The model trained here beside the shipped one (models/medium, trained on the medium_plus
  # data set by scripts/train_shipped.sh), on the same test split, each network alone and with
  # its post-processing, against every baseline bare and with the same post-processing; ends by
  # printing the table and each model against its best baseline.
  shipped=()
  [ -f models/medium/model.h5 ] && shipped=(--checkpoint models/medium/model.h5 --name "default (trained here)" --name "shipped (medium data)")
  "$bin" eval --run runs/default "${shipped[@]}" --dataset "$data" --constraints off,on \
    --out runs/default/eval
fi
