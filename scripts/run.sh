#!/usr/bin/env bash
# Everything needed on a fresh Debian 12 machine, then the main job on the built-in default: the
# whole loop on the open-drawer task against the proxy-reality drawer world, started
# automatically (`twinforge run`): scan, twin, 15 teleoperated demos, BC, inverse distillation,
# the PPO + BC teacher, teacher-student distillation, evaluation on the proxy reality at levels
# 1-3 against BC, and runs/open_drawer/eval/report.html. About an hour on 2 cores.
# Running it again skips the finished stages (a killed run resumes where it stopped).
# usage: scripts/run.sh [`twinforge run` flags, e.g. --config assets/runs/mug_on_shelf.json
#        --out runs/mug]. Without flags: task open_drawer, reality proxy:open_drawer (the task's
#        own world), out runs/open_drawer, which are `run`'s defaults.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
bash scripts/build.sh
tf=${TWINFORGE_BUILD_DIR:-build}/src/app/twinforge
"$tf" doctor
# `run` prints where the report is.
"$tf" run "$@"
