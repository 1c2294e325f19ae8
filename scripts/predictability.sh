#!/usr/bin/env bash
# How far can any simulator follow the ground truth, and how much of it is the wind?
# Re-simulates each sequence of a split (the test split unless SPLIT says otherwise) of a
# `layersnet generate` data set with the same seed and scene but one change, and scores these
# twins against the data with `layersnet eval --replay`, beside the baselines:
#   jitter     the cloth's starting vertices nudged by Gaussian noise (`cloth_jitter`, scene
#              units): how predictable the solver's cloth is;
#   calm-wind  every wind strength times 0 (`wind_scale`): how far the cloth moves because of
#              the wind (a model that ignored the wind could not get closer than this twin);
#              `layersnet eval --wind-scale 0 --wind-twins OUT/calm_wind` grades the models'
#              wind response against these twins.
# The first sequence is also re-simulated unchanged: Blender must reproduce it exactly (error 0),
# or the comparison means nothing.
#
#   scripts/predictability.sh [DATA] [OUT] [JITTER] [TWINS]
#     DATA    data set made by `layersnet generate` (default data/medium)
#     OUT     output folder (default runs/predictability); resumable: finished twins are kept
#     JITTER  noise std in scene units (default 0.01 = 1 mm at the D-LAYERS x10 scale)
#     TWINS   jitter (default) | calm-wind | both
# Environment: SPLIT=val twins that split's sequences instead of the test split's; IDS="00744
# 00745" re-simulates only these sequences of it (default: the whole split); EVAL_FRAMES=N
# scores N frames from the ramp's end (default: eval.frames); THREADS=N Blender threads per twin
# (default 2) must be those the data was made with (`generate --threads`, the reports'
# blender_threads): the cloth solver sums in a thread-dependent order, so another
# count is another trajectory (12.3 mm apart over 78 frames on a large-recipe sequence).
# Cost: one Blender run per twin (about 1 min per 100-frame sequence on 2 cores).
set -euo pipefail
cd "$(dirname "$0")/.."
DATA=${1:-data/medium}
OUT=${2:-runs/predictability}
JITTER=${3:-0.01}
TWINS=${4:-jitter}
BIN=${LAYERSNET:-build/bin/layersnet}
PY=/usr/bin/python3

case "$TWINS" in
  jitter) variants="jitter" ;;
  calm-wind) variants="calm_wind" ;;
  both) variants="jitter calm_wind" ;;
  *) echo "predictability: TWINS must be jitter, calm-wind or both, not '$TWINS'" >&2; exit 2 ;;
esac
[ -f "$DATA/dataset.json" ] || { echo "predictability: $DATA/dataset.json not found; make the data with layersnet generate" >&2; exit 2; }
[ -f "$DATA/scene.json" ] || { echo "predictability: $DATA/scene.json not found: only data sets of layersnet generate can be re-simulated" >&2; exit 2; }
mkdir -p "$OUT"
SPLIT=${SPLIT:-test}
ids=${IDS:-$($PY -c 'import json,sys; print(" ".join(json.load(open(sys.argv[1]))["splits"][sys.argv[2]]))' "$DATA/dataset.json" "$SPLIT")}
select=(--sequences "$(echo $ids | tr ' ' ',')")
[ -n "${EVAL_FRAMES:-}" ] && select+=(--frames "$EVAL_FRAMES")

# make_twins VARIANT KEY VALUE IDS...: the sequences IDS re-simulated with scene key KEY = VALUE.
make_twins() {
  local variant=$1 key=$2 value=$3
  shift 3
  local dir="$OUT/$variant"
  mkdir -p "$dir/logs" "$dir/reports"
  $PY -c 'import json,sys; s=json.load(open(sys.argv[1])); s[sys.argv[2]]=float(sys.argv[3]); json.dump(s, open(sys.argv[4], "w"))' \
    "$DATA/scene.json" "$key" "$value" "$dir/scene.json"
  cp "$DATA/dataset.json" "$dir/dataset.json"
  for id in "$@"; do
    [ -f "$dir/$id.h5" ] && continue
    read -r seed split < <($PY -c 'import json,sys; r=json.load(open(sys.argv[1])); print(r["seed"], r["split"])' "$DATA/reports/$id.json")
    echo "predictability: $variant twin of $id (seed $seed, $key $value)"
    blender -b --factory-startup -t "${THREADS:-2}" --python generate/make_sequence.py -- --out "$dir/$id.h5.part" \
      --report "$dir/reports/$id.json" --seed "$seed" --split "$split" --config "$dir/scene.json" > "$dir/logs/$id.log" 2>&1 \
      || { echo "predictability: Blender failed on $id, see $dir/logs/$id.log" >&2; exit 1; }
    mv "$dir/$id.h5.part" "$dir/$id.h5"
  done
}

make_twins same cloth_jitter 0 "${ids%% *}"
"$BIN" eval --dataset "$DATA" --split "$SPLIT" --sequences "${ids%% *}" "${select[@]:2}" --replay "$OUT/same" --name "re-simulated, unchanged" \
  --out "$OUT/eval_unchanged"
$PY -c 'import json,sys
m = next(m for m in json.load(open(sys.argv[1]))["methods"] if m["kind"] == "replay")
e = m["summary"]["error_mm"]["mean"]
sys.exit(f"predictability: the unchanged re-simulation differs from the data by {e} mm: Blender is not deterministic here, so the twins measure nothing" if e != 0 else 0)' \
  "$OUT/eval_unchanged/eval.json"

for variant in $variants; do
  if [ "$variant" = jitter ]; then
    make_twins jitter cloth_jitter "$JITTER" $ids
    "$BIN" eval --dataset "$DATA" --split "$SPLIT" "${select[@]}" --replay "$OUT/jitter" --name "re-simulated, cloth nudged ${JITTER} units" \
      --out "$OUT/eval"
  else
    make_twins calm_wind wind_scale 0 $ids
    "$BIN" eval --dataset "$DATA" --split "$SPLIT" "${select[@]}" --replay "$OUT/calm_wind" --name "re-simulated without wind" \
      --out "$OUT/eval_calm_wind"
  fi
done
