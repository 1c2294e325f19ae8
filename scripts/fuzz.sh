#!/usr/bin/env bash
# Fuzz every reader of untrusted files with libFuzzer (clang from Debian): the sequence reader
# (fuzz/fuzz_reader.cpp), checkpoint loading (fuzz/fuzz_checkpoint.cpp), and the files a user
# hands `simulate`: OBJ, PC2, wind CSV and BVH (fuzz/fuzz_user_files.cpp).
# Not part of the test suite. Usage: scripts/fuzz.sh [SECONDS=120] [JOBS=1] [TARGETS="reader checkpoint user"]
# Builds into build-fuzz/ with ASan + UBSan (rebuilt only when their sources changed), seeds
# each corpus from valid files, runs each target for SECONDS in libFuzzer's fork mode,
# prints the executions run, and exits non-zero on any crash, hang (10 s) or sanitizer report
# (each input is left in build-fuzz/ as crash-*, timeout-*, leak-*). The readers go through
# the program's guard (dataset/h5_guard.h): libhdf5 1.10.8 crashes or loops forever on some
# corrupt files (inputs kept in fuzz/known_hdf5_issues/, stacks inside H5HG_read), and the
# guard reads each file first in a child with a time limit (3 s here), so such files must
# come back as errors. Findings are classified by their first frame (our code or libhdf5).
# Leaks of memory allocated inside libhdf5 on the error paths of corrupt files are
# suppressed by fuzz/lsan.supp; every other leak is reported.
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
TARGETS="${3:-reader checkpoint user}"
# A version header as the CMake build generates it (checkpoints record the program).
mkdir -p "$OUT/generated"
version=$(sed -n 's/^project(layersnet VERSION \([0-9.]*\).*/\1/p' CMakeLists.txt)
sed "s/@PROJECT_VERSION@/${version:-0.0.0}/" cli/version.h.in > "$OUT/generated/layersnet_version.h"
CXXFLAGS+=(-I"$OUT/generated")
READER_SOURCES=(dataset/*.cpp)
CHECKPOINT_SOURCES=(dataset/*.cpp autodiff/params.cpp autodiff/arena.cpp autodiff/aligned_new.cpp model/params_layout.cpp run/checkpoint.cpp run/config.cpp run/run_dir.cpp)
SAN=(-fsanitize=fuzzer,address,undefined -fno-sanitize-recover=undefined)
if [[ " $TARGETS " == *" reader "* ]] &&
   [[ ! -x "$OUT/fuzz_reader" || -n "$(find dataset fuzz -newer "$OUT/fuzz_reader" -type f | head -1)" ]]; then
  echo "building $OUT/fuzz_reader (clang++, -fsanitize=fuzzer,address,undefined)"
  clang++ "${CXXFLAGS[@]}" "${SAN[@]}" fuzz/fuzz_reader.cpp "${READER_SOURCES[@]}" $HDF5_LIBS -lgomp -o "$OUT/fuzz_reader"
  clang++ "${CXXFLAGS[@]}" fuzz/make_seeds.cpp "${READER_SOURCES[@]}" $HDF5_LIBS -lgomp -o "$OUT/make_seeds"
fi
if [[ " $TARGETS " == *" checkpoint "* ]] &&
   [[ ! -x "$OUT/fuzz_checkpoint" || -n "$(find dataset autodiff model train fuzz -newer "$OUT/fuzz_checkpoint" -type f | head -1)" ]]; then
  echo "building $OUT/fuzz_checkpoint (clang++, -fsanitize=fuzzer,address,undefined)"
  clang++ "${CXXFLAGS[@]}" "${SAN[@]}" fuzz/fuzz_checkpoint.cpp "${CHECKPOINT_SOURCES[@]}" $HDF5_LIBS -lgomp \
    -o "$OUT/fuzz_checkpoint"
  clang++ "${CXXFLAGS[@]}" fuzz/make_checkpoint_seeds.cpp "${CHECKPOINT_SOURCES[@]}" $HDF5_LIBS -lgomp \
    -o "$OUT/make_checkpoint_seeds"
fi
USER_SOURCES=(dataset/*.cpp simulate/wind.cpp simulate/motion.cpp)
if [[ " $TARGETS " == *" user "* ]] &&
   [[ ! -x "$OUT/fuzz_user_files" || -n "$(find dataset simulate fuzz -newer "$OUT/fuzz_user_files" -type f | head -1)" ]]; then
  echo "building $OUT/fuzz_user_files (clang++, -fsanitize=fuzzer,address,undefined)"
  clang++ "${CXXFLAGS[@]}" "${SAN[@]}" fuzz/fuzz_user_files.cpp "${USER_SOURCES[@]}" $HDF5_LIBS -lgomp \
    -o "$OUT/fuzz_user_files"
fi
[[ " $TARGETS " != *" reader "* ]] || "$OUT/make_seeds" "$OUT/seeds"
if [[ " $TARGETS " == *" user "* ]]; then
  # Seeds: one valid file per reader, prefixed with its mode byte (fuzz/fuzz_user_files.cpp).
  mkdir -p "$OUT/seeds_user"
  { printf '\x00'; printf 'v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\nf 1/1 2/2 3/3 4/4\n'; } > "$OUT/seeds_user/obj"
  { printf '\x01'; python3 -c 'import struct,sys; sys.stdout.buffer.write(b"POINTCACHE2\0" + struct.pack("<iiffi", 1, 2, 0, 1, 2) + struct.pack("<12f", *range(12)))'; } > "$OUT/seeds_user/pc2"
  { printf '\x02'; printf 'frame,dx,dy,dz,strength\n0,1,0,0,400\n10,0,1,0,0\n'; } > "$OUT/seeds_user/csv"
  { printf '\x03'; printf 'HIERARCHY\nROOT Hips\n{\n OFFSET 0 0 0\n CHANNELS 6 Xposition Yposition Zposition Zrotation Yrotation Xrotation\n JOINT LeftUpLeg\n {\n  OFFSET 1 0 0\n  CHANNELS 3 Zrotation Yrotation Xrotation\n  End Site\n  {\n   OFFSET 0 -1 0\n  }\n }\n}\nMOTION\nFrames: 2\nFrame Time: 0.0083333\n0 0 0 0 0 0 0 0 0\n1 2 3 4 5 6 7 8 9\n'; } > "$OUT/seeds_user/bvh"
fi
[[ " $TARGETS " != *" checkpoint "* ]] || "$OUT/make_checkpoint_seeds" "$OUT/seeds_checkpoint" configs/tiny.toml
cd "$OUT"
export LSAN_OPTIONS="suppressions=$(pwd)/../fuzz/lsan.supp:print_suppressions=0"
# libhdf5 asks malloc for absurd sizes when a corrupt object header claims them (input
# fuzz/known_hdf5_issues/h5c_protect_huge_malloc, malloc from H5C_protect); in production
# malloc returns NULL and HDF5 fails cleanly, so let ASan's malloc do the same.
export ASAN_OPTIONS="allocator_may_return_null=1"
export LAYERSNET_HDF5_GUARD_SECONDS=3
failed=0
# run_target NAME MAX_LEN: fuzz build-fuzz/fuzz_NAME for SECONDS, then classify its findings.
run_target() {
  local name=$1 max_len=$2 corpus=corpus_$1 seeds=seeds
  [[ $name == reader ]] && corpus=corpus
  [[ $name == checkpoint ]] && seeds=seeds_checkpoint
  [[ $name == user_files ]] && seeds=seeds_user
  mkdir -p "$corpus" "findings_$name"
  echo "fuzzing $name for ${SECONDS_TO_RUN} s"
  rm -f crash-* leak-* timeout-* oom-*
  set +e
  # Crashes do not stop the run (-ignore_crashes=1): each one is classified afterwards by the
  # first stack frame that is not a sanitizer runtime frame (our code or libhdf5).
  "./fuzz_$name" -fork="$JOBS" -ignore_timeouts=1 -ignore_ooms=0 -ignore_crashes=1 \
    -max_total_time="$SECONDS_TO_RUN" -rss_limit_mb=2048 -max_len="$max_len" -timeout=10 \
    "$corpus" "$seeds" > "fuzz_$name.log" 2>&1
  grep -E "^#[0-9]+: cov" "fuzz_$name.log" | tail -1
  grep -E "INFO: fuzzed for" "fuzz_$name.log" | tail -1
  set -e
  local ours=0 hdf5=0 contained=0 f frame
  for f in crash-* leak-* oom-*; do
    [[ -e "$f" ]] || continue
    # The guard's child inherits libFuzzer's death callback, so a sanitizer report inside the
    # child (libhdf5 reading a corrupt file) leaves a crash-* file although the program refused
    # the file cleanly: an input that runs clean again counts as contained, not as a finding.
    if "./fuzz_$name" "$f" > /dev/null 2>&1; then
      contained=$((contained + 1))
      rm -f "$f"
      continue
    fi
    frame=$("./fuzz_$name" "$f" 2>&1 | grep -E "^ +#[0-9]+ 0x" |
            grep -v -E "__interceptor|__asan|__sanitizer|__lsan|in malloc|in calloc|in realloc|in free|operator new|fuzzer::" |
            head -1 || true)
    if [[ "$frame" == *libhdf5* ]]; then
      hdf5=$((hdf5 + 1))
    else
      ours=$((ours + 1))
      echo "FINDING in our code: $OUT/findings_$name/$f: $frame"
    fi
    mv "$f" "findings_$name/"
  done
  local hangs
  hangs=$(find . -maxdepth 1 -name "timeout-*" | wc -l)
  mv timeout-* "findings_$name/" 2>/dev/null || true
  echo "$name findings: $ours in our code, $hdf5 inside libhdf5, $hangs hangs; $contained inputs contained by the guard (refused, no crash); log: $OUT/fuzz_$name.log"
  [[ $ours -eq 0 && $hdf5 -eq 0 && $hangs -eq 0 ]] || failed=1
}
[[ " $TARGETS " != *" reader "* ]] || run_target reader 65536
[[ " $TARGETS " != *" checkpoint "* ]] || run_target checkpoint 262144
[[ " $TARGETS " != *" user "* ]] || run_target user_files 65536
exit $failed
