#!/usr/bin/env bash
# Everything needed on a fresh Debian 12 machine, then the main job on the built-in default.
# Until the full pipeline lands (issue 9), the main job is the simulation demo: check the
# machine, run the open-drawer scripted expert in the twin and write frames of one episode.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
bash scripts/build.sh
tf=${TWINFORGE_BUILD_DIR:-build}/src/app/twinforge
"$tf" doctor
