#!/usr/bin/env bash
# Everything needed on a fresh Debian 12 machine, then the test suite:
#   install packages -> build -> ctest.
# Slow end-to-end checks carry the ctest label "slow"; they are skipped when CI=true unless
# TWINFORGE_FULL_TESTS=1.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
bash scripts/build.sh
args=(--output-on-failure -j 2 --timeout 900)
if [ "${CI:-}" = "true" ] && [ "${TWINFORGE_FULL_TESTS:-0}" != "1" ]; then
  args+=(-LE slow)
fi
cd "${TWINFORGE_BUILD_DIR:-build}"
ctest "${args[@]}"
