#!/usr/bin/env bash
# Everything needed on a fresh Debian 12 machine, then the main job on the built-in default.
# Until the full pipeline lands (issue 9), the main job is the simulation demo: check the
# machine, measure the open-drawer scripted expert at each randomization level, benchmark the
# simulator, and write PNG frames of one episode to runs/demo/frames/.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
bash scripts/build.sh
tf=${TWINFORGE_BUILD_DIR:-build}/src/app/twinforge
out=runs/demo
mkdir -p "$out"
"$tf" doctor
for level in 1 2 3; do
  "$tf" sim expert --task open_drawer --episodes 100 --level "$level" | tee "$out/expert_level$level.json"
done
"$tf" sim bench --task open_drawer | tee "$out/bench.json"
"$tf" sim view --task open_drawer --level 1 --out "$out/frames"
echo "main job done: results in $out/"
