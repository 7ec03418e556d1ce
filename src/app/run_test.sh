#!/usr/bin/env bash
# The main job on the smoke budget (assets/runs/smoke.json): killed outright while training, then
# run again. The finished stages are skipped, the killed one resumes, the rest run, the report and
# both evaluations are written, and no proxy-reality server outlives its pipeline. New sim demos
# make the teacher start over. The student distilled without the real demos (RialTo's ablation)
# reruns only distillation and the student's evaluation.
# usage: run_test.sh TWINFORGE_BINARY SOURCE_DIR
set -euo pipefail
tf=$1
src=$2
d=$(mktemp -d)
trap 'rm -rf "$d"' EXIT
# A check or a run that fails says which, with the runs' logs (a failing run exits silently).
trap 'echo "run_test.sh: line $LINENO failed" >&2; tail -n 20 "$d"/*.log >&2' ERR
"$tf" run --config "$src/assets/runs/smoke.json" --out "$d/run" 2> "$d/first.log" &
pid=$!
# Kill once the teacher's training has started (its checkpoint is written every iteration). On a
# loaded machine the stages before it can take minutes: wait up to 5, and never kill earlier
# (a kill before the teacher starts would leave inverse distillation to run again).
for _ in $(seq 1 3000); do
  [ -f "$d/run/policies/teacher.ckpt" ] && break
  kill -0 $pid 2> /dev/null || { cat "$d/first.log" >&2; echo "the run ended early" >&2; exit 1; }
  sleep 0.1
done
[ -f "$d/run/policies/teacher.ckpt" ] ||
  { kill -9 $pid; cat "$d/first.log" >&2; echo "the teacher did not start in 5 min" >&2; exit 1; }
kill -9 $pid
wait $pid 2> /dev/null || true
sleep 0.5
if pgrep -f "reality serve --world open_drawer --port [0-9]* --parent $pid" > /dev/null; then
  echo "the killed run's proxy reality is still running" >&2
  exit 1
fi
grep -q '"bc"' "$d/run/manifest.json"
if grep -q '"rl"' "$d/run/manifest.json"; then echo "rl recorded before it finished" >&2; exit 1; fi
"$tf" run --config "$src/assets/runs/smoke.json" --out "$d/run" > "$d/out.json" 2> "$d/second.log"
for stage in scan twin calibrate sysid demos bc inverse_distill; do
  grep -q "stage [0-9]*/12 $stage: up to date" "$d/second.log" ||
    { echo "stage $stage ran again" >&2; cat "$d/second.log" >&2; exit 1; }
done
grep -q "resum" "$d/second.log" || { echo "rl did not resume its checkpoint" >&2; exit 1; }
# The smoke budget is a time cap alone: the run says its teacher depends on the machine's speed.
grep -q "rl: the teacher stopped at rl_minutes (0.25) after [0-9]* iterations: " "$d/second.log" ||
  { echo "no warning that a time cap stopped the teacher" >&2; exit 1; }
grep -q "distill: co-training with [1-9][0-9]* real steps" "$d/second.log"
for f in eval/report.html eval/student.json eval/bc_real.json eval/student.jsonl \
  policies/student.pt policies/teacher.pt eval/twin_view.png calibrated/calibration/frame_00.png \
  calibrated/calibration/mesh.json \
  identified/sysid/sysid.json; do
  [ -s "$d/run/$f" ] || { echo "missing $f" >&2; exit 1; }
done
grep -q "Success on reality" "$d/run/eval/report.html"
grep -q "Physics identified on the robot" "$d/run/eval/report.html"
grep -q "The scanned meshes" "$d/run/eval/report.html"
grep -q "Objects placed on the table by the same frames" "$d/run/eval/report.html"
# sysid measured the proxy arm's lagging servo: the identified twin's has a latency.
if grep -q "latency: 0$" "$d/run/identified/task.yaml"; then
  echo "the identified twin's servo has no latency" >&2
  exit 1
fi
[ "$(wc -l < "$d/run/eval/student.jsonl")" -eq 5 ]  # header + 2 levels x 2 trials
# A third run has nothing left to do but the report.
"$tf" run --config "$src/assets/runs/smoke.json" --out "$d/run" > /dev/null 2> "$d/third.log"
[ "$(grep -c 'up to date' "$d/third.log")" -eq 11 ]
# New sim demos (from the twin's scripted operator instead of inverse distillation): the teacher
# starts over rather than resuming a checkpoint made from the old ones. Its budget is now
# iterations, as the default's: it stops at 3 whatever the machine, and no warning is given.
"$tf" run --config "$src/assets/runs/smoke.json" --out "$d/run" --sim-demos expert \
  --rl-iterations 3 --rl-minutes 0 > /dev/null 2> "$d/fourth.log"
grep -q '"source": "expert"' "$d/run/demos/sim.json" || { echo "sim demos not remade" >&2; exit 1; }
grep -q "the teacher starts over" "$d/fourth.log" ||
  { echo "rl did not start over" >&2; cat "$d/fourth.log" >&2; exit 1; }
grep -q '"iterations": 3,' "$d/run/policies/teacher.json" &&
  grep -q '"stopped_by": "iterations"' "$d/run/policies/teacher.json" ||
  { echo "the teacher did not stop at its 3 iterations" >&2; cat "$d/run/policies/teacher.json" >&2; exit 1; }
if grep -q "stopped at rl_minutes" "$d/fourth.log"; then echo "a warning with no time cap" >&2; exit 1; fi
if grep -q "rl: resuming" "$d/fourth.log"; then
  echo "rl resumed a checkpoint made from other sim demos" >&2
  exit 1
fi
# RialTo's ablation, from the run's own options: the student distilled without the real demos.
# Only the distillation and what follows it run again.
"$tf" run --config "$d/run/config.json" --out "$d/run" --no-co-train > /dev/null 2> "$d/fifth.log"
grep -q "distill: sim data only" "$d/fifth.log"
[ "$(grep -c 'up to date' "$d/fifth.log")" -eq 9 ] ||
  { echo "the ablation ran more than distillation and evaluation" >&2; cat "$d/fifth.log" >&2; exit 1; }
grep -q '"co_train": false' "$d/run/config.json"
# Diagnosis on a proxy world: each trial's line carries the world's hidden end state, and the
# step trace one line per action sent, with the hidden state then. A real robot's address is
# refused: it has none to read.
"$tf" eval --policy "$d/run/policies/student.pt" --task open_drawer --reality proxy:open_drawer \
  --levels 1 --trials 2 --grader-state --trace "$d/trace.jsonl" --out "$d/graded.jsonl" \
  > /dev/null 2> "$d/graded.log"
[ "$(grep -c '"grader":{.*"drawer_slide":.*"object_quats":{"chest":\[[^]]*\]' "$d/graded.jsonl")" -eq 2 ]
steps=$(grep -o '"steps":[0-9]*' "$d/graded.jsonl" | awk -F: '{s += $2} END {print s + 0}')
[ "$steps" -gt 0 ] && [ "$(wc -l < "$d/trace.jsonl")" -eq "$steps" ] ||
  { echo "trace: $(wc -l < "$d/trace.jsonl") lines for $steps steps" >&2; exit 1; }
[ "$(grep -c '"action":"[^"]*".*"grader":{.*"q":\[[^]]*\].*"tool":\[.*"tool_quat":\[' "$d/trace.jsonl")" -eq "$steps" ]
if "$tf" eval --policy "$d/run/policies/student.pt" --task open_drawer \
  --reality tcp://127.0.0.1:9 --grader-state --out "$d/refused.jsonl" 2> "$d/refused.log"; then
  echo "--grader-state accepted a real robot's address" >&2
  exit 1
fi
grep -q "must be proxy:WORLD" "$d/refused.log"
echo ALL-GOOD
