#!/usr/bin/env bash
# The whole test suite: set up (install + build), then every CTest test. Among them the build is
# installed into a prefix and run from there (tests/install), and the repository is checked to
# need nothing beside it (tests/repository). A skipped test fails the run: setup installs every
# dependency, so a skip means something is missing.
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
bash scripts/setup.sh
log=$(mktemp)
trap 'rm -f "$log"' EXIT
run=(ctest --test-dir build --output-on-failure -j "$(nproc 2>/dev/null || echo 2)" "$@")
# Outside reference material may sit beside a clone (../shared); the tests must not need it, so
# where the system lets us (root, mount namespaces) they run with that folder hidden.
if [[ -d ../shared ]] && unshare -m true 2>/dev/null; then
  echo "test.sh: running the tests with $(cd .. && pwd)/shared hidden"
  unshare -m sh -c 'mount -t tmpfs none ../shared && exec "$@"' sh "${run[@]}" 2>&1 | tee "$log"
else
  "${run[@]}" 2>&1 | tee "$log"
fi
if grep -q '\*\*\*Skipped' "$log"; then
  echo "test.sh: skipped tests (a dependency is missing; scripts/setup.sh installs them):" >&2
  grep '\*\*\*Skipped' "$log" >&2
  exit 1
fi
