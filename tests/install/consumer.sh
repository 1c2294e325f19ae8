#!/usr/bin/env bash
# Builds the consumer project (tests/install/consumer) against an install prefix with
# find_package(layersnet), warning-free, and runs it on the prefix's shipped model.
# Usage: consumer.sh PREFIX SOURCE_DIR CXX_COMPILER
set -euo pipefail
prefix=$(realpath "$1")
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
log=$work/log.txt
cmake -S "$2/tests/install/consumer" -B "$work/build" -DCMAKE_PREFIX_PATH="$prefix" -DCMAKE_CXX_COMPILER="$3" \
  > "$log" 2>&1 || { cat "$log"; exit 1; }
cmake --build "$work/build" > "$log" 2>&1 || { cat "$log"; exit 1; }
if grep -q 'warning:' "$log"; then cat "$log"; echo "consumer.sh: the consumer built with warnings" >&2; exit 1; fi
"$work/build/consumer" "$prefix/share/layersnet/models/medium/model.h5"
