#include "real2sim/calibrate/sysid_bench.h"

#include "core/measure.h"
#include "real2sim/calibrate/robot_sysid.h"
#include "sim/bench.h"

namespace twinforge::real2sim {

nlohmann::json RunSysidBench(const sim::TaskSpec& task, const SysidBenchOptions& options) {
  // "The robot": the twin's arm lagging 25 ms and softer (the drawer proxy's), its free moves
  // recorded in the twin.
  TwinReplay replay(task);
  RobotPhysics robot;
  robot.servo = {0.3, 0.025};
  robot.arm = {0.75, 1.4, 1.5, 2.0};
  robot.grip_force = replay.NominalGripForce();
  RobotTrajectory free;
  free.name = "free";
  free.targets = FreeArmTargets(task);
  free.q = replay.Run(robot, {}, free.targets, &free.gripper_width);
  RobotSysidOptions sysid;
  sysid.controller.iterations = options.iterations;
  auto fit = [&](int threads) {
    sysid.threads = threads;
    return IdentifyRobotPhysics(task, {}, {free}, {}, sysid);
  };

  // Baseline: raw mj_step on copies of the twin's model from its level-0 start.
  sim::Env start(std::make_shared<const sim::Task>(task));
  start.Reset(0, 0);

  // Each repeat measures everything back to back, so ratios compare runs seconds apart on a
  // shared, noisy machine; medians over repeats.
  std::vector<double> raw1, raw2, fit1, fit2, raw_scaling, speedup, of_ceiling, overhead;
  bool same = true;
  int replays = 0;
  const double steps_per_replay = static_cast<double>(free.targets.size()) * task.control.substeps;
  for (int r = 0; r < options.repeats; ++r) {
    const sim::RawStepRates raw = sim::MeasureRawSteps(start, options.raw_steps, 7 + 2 * r);
    RobotSysidResult a, b;
    const double t1 = core::Seconds([&] { a = fit(1); });
    const double t2 = core::Seconds([&] { b = fit(2); });
    const RobotPhysics &x = a.identified, &y = b.identified;
    same = same && x.servo.interpolation == y.servo.interpolation &&
           x.servo.latency == y.servo.latency && x.arm.kp == y.arm.kp && x.arm.kd == y.arm.kd &&
           x.arm.damping == y.arm.damping && x.arm.frictionloss == y.arm.frictionloss &&
           x.grip_force == y.grip_force && a.controller_curve == b.controller_curve &&
           a.replays == b.replays;
    replays = a.replays;
    raw1.push_back(raw.one);
    raw2.push_back(raw.two);
    fit1.push_back(t1);
    fit2.push_back(t2);
    raw_scaling.push_back(raw2.back() / raw1.back());
    speedup.push_back(t1 / t2);
    of_ceiling.push_back(speedup.back() / raw_scaling.back());
    overhead.push_back(raw1.back() / (replays * steps_per_replay / t1) - 1);
  }
  return {{"task", task.name},
          {"repeats", options.repeats},
          {"replays_per_fit", replays},
          {"raw_mj_step_per_s", core::Median(raw1)},
          {"raw_mj_step_per_s_2_threads", core::Median(raw2)},
          {"raw_scaling_2_threads", core::Median(raw_scaling)},
          {"fit_seconds_1_thread", core::Median(fit1)},
          {"fit_seconds_2_threads", core::Median(fit2)},
          {"fit_speedup_2_threads", core::Median(speedup)},
          {"fit_speedup_of_raw_scaling", core::Median(of_ceiling)},
          {"replay_overhead_vs_raw", core::Median(overhead)},
          {"same_fit_on_1_and_2_threads", same}};
}

}  // namespace twinforge::real2sim
