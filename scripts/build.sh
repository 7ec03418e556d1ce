#!/usr/bin/env bash
# Configures and builds twinforge (Release) into build/. Extra arguments go to CMake, e.g.
#   scripts/build.sh -DTWINFORGE_SANITIZE=ON
set -euo pipefail
cd "$(dirname "$0")/.."
build_dir=${TWINFORGE_BUILD_DIR:-build}
cmake -S . -B "$build_dir" -G Ninja -DCMAKE_BUILD_TYPE=${CMAKE_BUILD_TYPE:-Release} "$@" >/dev/null
# Two compile jobs: the machines have two cores and LibTorch translation units need ~2 GB each.
cmake --build "$build_dir" -j "${TWINFORGE_JOBS:-2}"
