#!/usr/bin/env bash
# Fuzz the data layer's readers with libFuzzer (clang from Debian; see fuzz/fuzz_reader.cpp).
# Not part of the test suite. Usage: scripts/fuzz.sh [SECONDS=120] [JOBS=1]
# Builds into build-fuzz/ with ASan + UBSan (rebuilt only when dataset/ or fuzz/ changed),
# seeds a corpus from valid synthetic files, runs for SECONDS in libFuzzer's fork mode,
# prints the executions run; exits non-zero on any crash or sanitizer report (the input is
# left in build-fuzz/ as crash-*).
# Timeouts are ignored (-ignore_timeouts=1) because libhdf5 1.10.8 itself can loop forever
# on a corrupted global heap while reading a variable-length string attribute (an input is
# kept in fuzz/known_hdf5_issues/; the stack is inside H5HG_read, not in our code); they are
# counted in the final summary instead. Leaks of memory allocated inside libhdf5 on the error
# paths of corrupt files are suppressed by fuzz/lsan.supp; every other leak is reported.
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
SECONDS_TO_RUN="${1:-120}"
JOBS="${2:-1}"
OUT=build-fuzz
mkdir -p "$OUT/corpus"
HDF5_CFLAGS=$(pkg-config --cflags hdf5 2>/dev/null || echo "-I/usr/include/hdf5/serial")
HDF5_LIBS=$(pkg-config --libs hdf5 2>/dev/null || echo "-L/usr/lib/x86_64-linux-gnu/hdf5/serial -lhdf5")
CXXFLAGS=(-std=c++20 -O1 -g -fno-omit-frame-pointer -I. -I/usr/include/eigen3 $HDF5_CFLAGS -fopenmp=libgomp
          -Wno-unknown-pragmas)
SOURCES=(dataset/*.cpp)
if [[ ! -x "$OUT/fuzz_reader" || -n "$(find dataset fuzz -newer "$OUT/fuzz_reader" -type f | head -1)" ]]; then
  echo "building $OUT/fuzz_reader (clang++, -fsanitize=fuzzer,address,undefined)"
  clang++ "${CXXFLAGS[@]}" -fsanitize=fuzzer,address,undefined -fno-sanitize-recover=undefined \
    fuzz/fuzz_reader.cpp "${SOURCES[@]}" $HDF5_LIBS -lgomp -o "$OUT/fuzz_reader"
  clang++ "${CXXFLAGS[@]}" fuzz/make_seeds.cpp "${SOURCES[@]}" $HDF5_LIBS -lgomp -o "$OUT/make_seeds"
fi
"$OUT/make_seeds" "$OUT/seeds"
cd "$OUT"
export LSAN_OPTIONS="suppressions=$(pwd)/../fuzz/lsan.supp:print_suppressions=0"
echo "fuzzing for ${SECONDS_TO_RUN} s"
set +e
./fuzz_reader -fork="$JOBS" -ignore_timeouts=1 -ignore_ooms=0 -ignore_crashes=0 \
  -max_total_time="$SECONDS_TO_RUN" -rss_limit_mb=2048 -max_len=65536 -timeout=10 \
  corpus seeds 2>&1 | tee fuzz.log | \
  grep -E "^#[0-9]+: cov|ERROR|SUMMARY|INFO: fuzzed for|crash|timeout" | tail -20
status=${PIPESTATUS[0]}
set -e
echo "exit status $status; log: $OUT/fuzz.log"
exit "$status"
