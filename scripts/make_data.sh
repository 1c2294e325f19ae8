#!/usr/bin/env bash
# Makes (or resumes) every data set the validation and test figures in docs/decisions.md use, in
# the order in which the work needs them: data/default, the validation splits that choose
# (medium_choice, large, and large_unseen_val for the outfits the large set holds out), the large
# test split (small beside the training split, so that a model trained on the part of the
# training split made so far can already be evaluated), the large training split (the shipped
# large model's first LARGE_TRAIN sequences first), then the sleeves test set.
# Each step keeps the sequences already made, so the script can be stopped and run again; the
# data sets are not in the repository (about 5.5 MB per 100-frame sequence).
#
#   scripts/make_data.sh [JOBS=2]
# Environment: LAYERSNET=path of the binary (default build/bin/layersnet); LARGE_TRAIN, the
# training sequences scripts/train_shipped.sh large trains on (default 112, as there); run it
# from a frozen copy of the tree for long runs (generate/README.md, "Long runs").
set -euo pipefail
cd "$(dirname "$0")/.."
jobs=${1:-2}
bin=${LAYERSNET:-build/bin/layersnet}
[ -x "$bin" ] || { echo "make_data: $bin not found; build first (bash scripts/setup.sh)" >&2; exit 2; }
gen() { "$bin" generate --jobs "$jobs" --threads 1 --manifest-every 4 "$@"; }

gen --recipe generate/recipes/default.json --out data/default
"$bin" prepare data/default
gen --recipe generate/recipes/medium_choice.json --out data/medium_choice --splits val
gen --recipe generate/recipes/large.json --out data/large --splits val
gen --recipe generate/recipes/large_unseen_val.json --out data/large_unseen_val --splits val
gen --recipe generate/recipes/large.json --out data/large --splits test
# The shipped large model's training sequences first (scripts/train_shipped.sh large), then the rest.
gen --recipe generate/recipes/large.json --out data/large --splits train --train-limit "${LARGE_TRAIN:-112}"
gen --recipe generate/recipes/large.json --out data/large --splits train
"$bin" prepare data/large
gen --recipe generate/recipes/sleeves.json --out data/sleeves --splits test
