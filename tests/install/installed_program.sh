#!/usr/bin/env bash
# The installed program, run from a scratch folder outside the sources and the build tree, so
# it can only find its recipe, Blender script and shipped model under PREFIX/share/layersnet:
# generate a short sequence, cut an outfit and motion from it, simulate them with the default
# (shipped) model, evaluate the result.
# Usage: installed_program.sh PREFIX
set -euo pipefail
prefix=$(realpath "$1")
bin=$prefix/bin/layersnet
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
cd "$work"
fail() { echo "installed_program: $*" >&2; exit 1; }

"$bin" --version | grep -q '^layersnet [0-9]' || fail "--version"
"$bin" generate --help | grep -q -- '--recipe' || fail "generate --help"

"$bin" generate --out gen --count 1 --frames 12 --seed 3 > generate.log 2>&1 || { cat generate.log; fail "generate"; }
grep -q "$prefix/share/layersnet/generate/recipes/default.json" gen/generate_report.md || fail "generate: not the installed recipe"
blender -b --python "$prefix/share/layersnet/scripts/outfit_from_h5.py" -- gen/00000.h5 outfit > outfit.log 2>&1 ||
  { tail -20 outfit.log; fail "outfit_from_h5.py"; }

# The outfit script names its garments, inner to outer, in one line.
garments=$(sed -n 's/^outfit: \(.*\) (inner to outer).*/\1/p' outfit.log | tr -d ' ' | tr ',' ' ')
[ -n "$garments" ] || { cat outfit.log; fail "outfit_from_h5.py named no garments"; }
args=()
for g in $garments; do args+=(--garment "outfit/$g.obj"); done
"$bin" simulate "${args[@]}" --body-frames outfit/body --out sim > simulate.log 2>&1 || { cat simulate.log; fail "simulate"; }
grep -q "model $prefix/share/layersnet/models/large/model.h5" simulate.log || { cat simulate.log; fail "simulate: not the installed model"; }
inner=${garments%% *}
frames=$(ls outfit/body | wc -l)
[ "$(ls "sim/$inner" | wc -l)" -eq "$frames" ] || fail "simulate: $(ls "sim/$inner" | wc -l) $inner frames for $frames body frames"

"$bin" eval --checkpoint "$prefix/share/layersnet/models/medium/model.h5" --dataset sim --out ev > eval.log 2>&1 ||
  { cat eval.log; fail "eval"; }
[ -s ev/eval.json ] || fail "eval: no eval.json"
echo "installed_program: generate, simulate and eval ran from $prefix"
