#!/usr/bin/env bash
# Installs the missing Debian packages (scripts/debian-packages.txt), then configures
# and builds LayersNet in Release. Idempotent: a second run installs nothing and rebuilds
# only what changed.
#
# The build tree lives outside the sources, so that every run (CI's included) shows the
# program needs nothing from where it was built: $LAYERSNET_BUILD_DIR, else a folder under
# ~/.cache/layersnet named after this clone's path. build/ in the clone is a link to it; a
# clone that already has a build/ folder of its own keeps building there.
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."

mapfile -t wanted < <(sed -e 's/#.*//' -e 's/[[:space:]]*$//' scripts/debian-packages.txt | grep -v '^$' | awk '{print $1}')
missing=()
for pkg in "${wanted[@]}"; do
  if ! dpkg-query -W -f='${Status}' "$pkg" 2>/dev/null | grep -q 'install ok installed'; then
    missing+=("$pkg")
  fi
done
if [ ${#missing[@]} -gt 0 ]; then
  echo "setup: installing ${#missing[@]} Debian package(s): ${missing[*]}"
  sudo_cmd=()
  [ "$(id -u)" -ne 0 ] && sudo_cmd=(sudo)
  export DEBIAN_FRONTEND=noninteractive
  "${sudo_cmd[@]}" apt-get update -qq
  "${sudo_cmd[@]}" apt-get install -y -qq --no-install-recommends "${missing[@]}"
else
  echo "setup: all ${#wanted[@]} Debian packages present"
fi

if [ ! -e build ]; then
  tree=${LAYERSNET_BUILD_DIR:-${XDG_CACHE_HOME:-$HOME/.cache}/layersnet/build-$(pwd -P | sha1sum | cut -c1-12)}
  mkdir -p "$tree"
  ln -s "$tree" build
fi
tree=$(readlink -f build)
jobs=$(nproc 2>/dev/null || echo 2)
cmake -S . -B "$tree" -DCMAKE_BUILD_TYPE=Release > build.configure.log 2>&1 || { cat build.configure.log; exit 1; }
cmake --build "$tree" -j "$jobs"
echo "setup: built build/bin/layersnet in $tree ($(build/bin/layersnet --version))"
