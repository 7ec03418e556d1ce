#!/usr/bin/env bash
# Everything needed on a fresh Debian 12 machine, then the main job on the built-in default.
# Until the full pipeline lands (issue 9), the main job runs the stages built so far on the
# open-drawer task: check the machine, measure the scripted expert at each randomization level,
# benchmark the simulator, write PNG frames of one episode, scan the proxy-reality drawer world,
# build its twin, record 15 teleoperated demos, then BC, inverse distillation and the PPO + BC
# teacher in the twin (about 35 minutes on 2 cores), all under runs/demo/.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
bash scripts/build.sh
tf=${TWINFORGE_BUILD_DIR:-build}/src/app/twinforge
out=runs/demo
# The previous results are kept, once, in runs/demo.previous.
if [ -d "$out" ]; then rm -rf "$out.previous" && mv "$out" "$out.previous"; fi
mkdir -p "$out"
"$tf" doctor
for level in 1 2 3; do
  "$tf" sim expert --task open_drawer --episodes 100 --level "$level" | tee "$out/expert_level$level.json"
done
"$tf" sim bench --task open_drawer | tee "$out/bench.json"
"$tf" sim view --task open_drawer --level 1 --out "$out/frames"
"$tf" scan capture --reality proxy:open_drawer --task open_drawer --out "$out/scan" | tee "$out/scan.json"
"$tf" scan capture --reality proxy:open_drawer --task open_drawer --operate-first \
  --out "$out/scan_open" | tee "$out/scan_open.json"
"$tf" twin build --scan "$out/scan" --scan-after "$out/scan_open" --task open_drawer \
  --out "$out/twin" > "$out/twin_build.json"
"$tf" sim expert --task "$out/twin/task.yaml" --episodes 100 --level 1 | tee "$out/twin_expert.json"
"$tf" demos record --reality proxy:open_drawer --task open_drawer --n 15 --out "$out/real.hdf5" \
  | tee "$out/demos.json"
# BC on the demos, inverse distillation into the twin, the PPO + BC teacher and its evaluation.
TWINFORGE="$tf" bash scripts/learn_world.sh open_drawer "$out"
echo "main job done: results in $out/"
