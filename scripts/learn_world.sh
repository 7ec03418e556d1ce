#!/usr/bin/env bash
# RialTo's chain on one proxy-reality world, each stage's output kept under OUT:
#   scan (twice for a world with a moving part) -> twin -> 15 teleoperated demos -> BC ->
#   inverse distillation in the twin -> PPO + BC teacher in the twin -> the teacher's success per
#   level in the twin; with SCRATCH=1 also PPO from scratch (no demos) on the same budget.
# Stages whose output exists are skipped, so a stopped run picks up where it was.
# usage: scripts/learn_world.sh WORLD OUT   (env: MINUTES=20 THREADS=2 SCRATCH=0 DEMOS=15)
set -euo pipefail
world=$1
out=$2
tf=${TWINFORGE:-${TWINFORGE_BUILD_DIR:-build}/src/app/twinforge}
minutes=${MINUTES:-20}
threads=${THREADS:-2}
mkdir -p "$out"
stage() { echo "== $world: $1" >&2; }
# A world whose task has a joint is scanned again after the operator moves the part.
if grep -q '^joints:' "assets/tasks/$world/task.yaml"; then articulated=1; else articulated=0; fi
if [ ! -f "$out/twin/task.yaml" ]; then
  stage "scan and twin"
  "$tf" scan capture --reality "proxy:$world" --task "$world" --out "$out/scan" > "$out/scan.json"
  after=()
  if [ "$articulated" = 1 ]; then
    "$tf" scan capture --reality "proxy:$world" --task "$world" --operate-first \
      --out "$out/scan_open" > "$out/scan_open.json"
    after=(--scan-after "$out/scan_open")
  fi
  "$tf" twin build --scan "$out/scan" "${after[@]}" --task "$world" --out "$out/twin" \
    > "$out/twin_build.json"
fi
if [ ! -f "$out/real.hdf5" ]; then
  stage "record ${DEMOS:-15} demos"
  "$tf" demos record --reality "proxy:$world" --task "$world" --n "${DEMOS:-15}" \
    --out "$out/real.hdf5.part" > "$out/demos.json"
  mv "$out/real.hdf5.part" "$out/real.hdf5"
fi
if [ ! -f "$out/bc_real.pt" ]; then
  stage "BC on the real demos"
  "$tf" train bc --demos "$out/real.hdf5" --out "$out/bc_real.pt" > "$out/bc.json"
fi
if [ ! -f "$out/sim.hdf5" ]; then
  stage "inverse distillation"
  rm -f "$out/sim.hdf5.part"
  "$tf" train inverse-distill --policy "$out/bc_real.pt" --task "$world" --twin "$out/twin" \
    --n 12 --max-episodes 3000 --temperature 0.5 --threads "$threads" \
    --out "$out/sim.hdf5.part" > "$out/inverse_distill.json"
  mv "$out/sim.hdf5.part" "$out/sim.hdf5"
fi
stage "PPO + BC teacher (${minutes} min budget)"
"$tf" train rl --task "$world" --twin "$out/twin" --demos "$out/sim.hdf5" \
  --out "$out/teacher.pt" --minutes "$minutes" --threads "$threads" > "$out/rl.json"
"$tf" sim eval --policy "$out/teacher.pt" --task "$out/twin" --levels 1,2,3 --episodes 100 --sample \
  --threads "$threads" > "$out/teacher_eval.json"
if [ "${SCRATCH:-0}" = 1 ]; then
  stage "PPO from scratch (${minutes} min budget)"
  "$tf" train rl --task "$world" --twin "$out/twin" --demos none \
    --out "$out/scratch/teacher.pt" --minutes "$minutes" --threads "$threads" > "$out/rl_scratch.json"
fi
echo "$world: done, results in $out" >&2
