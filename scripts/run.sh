#!/usr/bin/env bash
# Everything needed on a fresh Debian 12 machine, then the main job on the built-in default: the
# whole loop on the open-drawer task against the proxy-reality drawer world, started
# automatically (`twinforge run`): scan, twin, 15 teleoperated demos, BC, inverse distillation,
# the PPO + BC teacher, teacher-student distillation, evaluation on the proxy reality at levels
# 1-3 against BC, and runs/open_drawer/eval/report.html. About an hour on 2 cores.
# Running it again skips the finished stages (a killed run resumes where it stopped).
# usage: scripts/run.sh [extra `twinforge run` flags, e.g. --task mug_on_shelf --out runs/mug]
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
bash scripts/build.sh
tf=${TWINFORGE_BUILD_DIR:-build}/src/app/twinforge
"$tf" doctor
"$tf" run --task open_drawer --reality proxy:open_drawer --out runs/open_drawer "$@"
echo "main job done: open runs/open_drawer/eval/report.html"
