#!/usr/bin/env bash
# How far can any simulator follow the ground truth? Re-simulates each test sequence of a
# `layersnet generate` data set with the same seed and scene but the cloth's starting vertices
# nudged by Gaussian noise (`cloth_jitter`, scene units), and scores these twins against the
# data with `layersnet eval --replay`, beside the baselines. The first sequence is also
# re-simulated unchanged: Blender must reproduce it exactly (error 0), or the comparison means
# nothing.
#
#   scripts/predictability.sh [DATA] [OUT] [JITTER]
#     DATA    data set made by `layersnet generate` (default data/medium)
#     OUT     output folder (default runs/predictability); resumable: finished twins are kept
#     JITTER  noise std in scene units (default 0.01 = 1 mm at the D-LAYERS x10 scale)
# Cost: one Blender run per twin (about 1 min per 100-frame sequence on 2 cores).
set -euo pipefail
cd "$(dirname "$0")/.."
DATA=${1:-data/medium}
OUT=${2:-runs/predictability}
JITTER=${3:-0.01}
BIN=${LAYERSNET:-build/bin/layersnet}
PY=/usr/bin/python3

[ -f "$DATA/dataset.json" ] || { echo "predictability: $DATA/dataset.json not found; make the data with layersnet generate" >&2; exit 2; }
[ -f "$DATA/scene.json" ] || { echo "predictability: $DATA/scene.json not found: only data sets of layersnet generate can be re-simulated" >&2; exit 2; }
mkdir -p "$OUT"
ids=$($PY -c 'import json,sys; print(" ".join(json.load(open(sys.argv[1]))["splits"]["test"]))' "$DATA/dataset.json")

first=${ids%% *}
for variant in same jitter; do
  dir="$OUT/$variant"
  mkdir -p "$dir/logs" "$dir/reports"
  jitter=0; [ "$variant" = jitter ] && jitter=$JITTER
  $PY -c 'import json,sys; s=json.load(open(sys.argv[1])); s["cloth_jitter"]=float(sys.argv[2]); json.dump(s, open(sys.argv[3], "w"))' \
    "$DATA/scene.json" "$jitter" "$dir/scene.json"
  cp "$DATA/dataset.json" "$dir/dataset.json"
  variant_ids=$ids; [ "$variant" = same ] && variant_ids=$first
  for id in $variant_ids; do
    [ -f "$dir/$id.h5" ] && continue
    read -r seed split < <($PY -c 'import json,sys; r=json.load(open(sys.argv[1])); print(r["seed"], r["split"])' "$DATA/reports/$id.json")
    echo "predictability: $variant twin of $id (seed $seed, cloth_jitter $jitter)"
    blender -b --factory-startup -t 2 --python generate/make_sequence.py -- --out "$dir/$id.h5.part" \
      --report "$dir/reports/$id.json" --seed "$seed" --split "$split" --config "$dir/scene.json" > "$dir/logs/$id.log" 2>&1 \
      || { echo "predictability: Blender failed on $id, see $dir/logs/$id.log" >&2; exit 1; }
    mv "$dir/$id.h5.part" "$dir/$id.h5"
  done
done

"$BIN" eval --dataset "$DATA" --split test --max-sequences 1 --replay "$OUT/same" --name "re-simulated, unchanged" \
  --out "$OUT/eval_unchanged"
$PY -c 'import json,sys
m = next(m for m in json.load(open(sys.argv[1]))["methods"] if m["kind"] == "replay")
e = m["summary"]["error_mm"]["mean"]
sys.exit(f"predictability: the unchanged re-simulation differs from the data by {e} mm: Blender is not deterministic here, so the twins measure nothing" if e != 0 else 0)' \
  "$OUT/eval_unchanged/eval.json"
"$BIN" eval --dataset "$DATA" --split test --replay "$OUT/jitter" --name "re-simulated, cloth nudged ${JITTER} units" \
  --out "$OUT/eval"
