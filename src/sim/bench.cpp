#include "sim/bench.h"

#include <algorithm>
#include <chrono>
#include <functional>
#include <thread>

#include "core/measure.h"
#include "sim/camera.h"
#include "sim/vec_env.h"

namespace twinforge::sim {

namespace {

// work()/seconds for one run, where work() returns the units it did.
double Rate(const std::function<double()>& work) {
  const auto start = core::Clock::now();
  const double units = work();
  return units / core::SecondsSince(start);
}

}  // namespace

RawStepRates MeasureRawSteps(const Env& reference, int steps, uint64_t seed) {
  const auto& robot = reference.task().index().robot;
  const int substeps = reference.task().spec().control.substeps;
  struct RawSim {
    ModelPtr model;
    DataPtr data;
    core::Rng rng;
  };
  auto make_raw = [&](uint64_t raw_seed) {
    RawSim sim{ModelPtr(mj_copyModel(nullptr, reference.model())), nullptr, core::Rng(raw_seed)};
    sim.data = MakeData(sim.model.get());
    return sim;
  };
  auto raw_steps = [&](RawSim& sim) {
    mjModel* m = sim.model.get();
    mjData* d = sim.data.get();
    mj_resetData(m, d);
    mju_copy(d->qpos, reference.data()->qpos, m->nq);
    mju_copy(d->ctrl, reference.data()->ctrl, m->nu);
    for (int i = 0; i < steps; ++i) {
      if (i % substeps == 0)
        for (int k = 0; k < kArmDof; ++k)
          d->ctrl[robot.arm_actuator[k]] =
              reference.data()->ctrl[robot.arm_actuator[k]] + sim.rng.Uniform(-0.05, 0.05);
      for (int k = 0; k < kArmDof; ++k)
        d->qfrc_applied[robot.arm_dof[k]] = d->qfrc_bias[robot.arm_dof[k]];
      mj_step(m, d);
    }
    return double(steps);
  };
  RawSim raw_a = make_raw(seed), raw_b = make_raw(seed + 1);
  RawStepRates rates;
  rates.one = Rate([&] { return raw_steps(raw_a); });
  rates.two = Rate([&] {
    std::thread other([&] { raw_steps(raw_b); });
    raw_steps(raw_a);
    other.join();
    return 2.0 * steps;
  });
  return rates;
}

nlohmann::json RunSimBench(std::shared_ptr<const Task> task, const BenchOptions& options) {
  const int substeps = task->spec().control.substeps;

  // Baseline: raw mj_step (MeasureRawSteps), its two-thread rate the ceiling for the VecEnv's
  // scaling.
  Env reference(task);
  reference.Reset(0, 1);

  // VecEnv physics steps with random discrete actions.
  VecEnv vec1(task, {.num_envs = options.num_envs, .threads = 1, .seed = 1, .level = 1});
  VecEnv vec2(task, {.num_envs = options.num_envs, .threads = 2, .seed = 1, .level = 1});
  std::vector<Action> actions(options.num_envs);
  core::Rng action_rng(9);
  auto vec_run = [&](VecEnv& vec) {
    vec.Reset();
    for (int t = 0; t < options.control_steps; ++t) {
      for (auto& a : actions) a = Action::Discrete(static_cast<int>(action_rng.Index(12)));
      vec.Step(actions.data());
    }
    return double(options.control_steps) * vec.num_envs() * substeps;
  };

  // Baselines: raw mj_ray and raw Embree casts, one ray per pixel of the task camera's image,
  // scene geoms only, the scene left where it is.
  CloudMaker maker(*task, reference.model(), {});
  const auto& k = maker.caster().camera().intrinsics;
  const int pixels = k.width * k.height;
  auto ray_direction = [&](int i) {
    return Eigen::Vector3d(-1.0, (i % k.width - k.width / 2) * 0.01, -0.7 + (i / k.width) * 0.01)
        .normalized();
  };
  const mjtNum origin[3] = {1.1, 0.0, 0.7};
  auto ray_run = [&] {
    mjtByte groups[mjNGROUP] = {1, 0, 1, 1, 1, 1};
    int geom = -1;
    for (int c = 0; c < options.clouds; ++c)
      for (int i = 0; i < pixels; ++i) {
        const Eigen::Vector3d dir = ray_direction(i);
        mj_ray(reference.model(), reference.data(), origin, dir.data(), groups, 1, -1, &geom);
      }
    return double(options.clouds) * pixels;
  };
  GeomScene& geoms = maker.caster().scene();
  geoms.Update(reference.model(), reference.data(), 1u << kRobotGeomGroup);
  auto embree_run = [&] {
    const float from[3] = {float(origin[0]), float(origin[1]), float(origin[2])};
    for (int c = 0; c < options.clouds; ++c)
      for (int i = 0; i < pixels; ++i) {
        const Eigen::Vector3f dir = ray_direction(i).cast<float>();
        geoms.Cast(from, dir.data());
      }
    return double(options.clouds) * pixels;
  };
  std::vector<float> scene(maker.options().scene_points * 3), arm(maker.options().arm_points * 3);
  core::Rng cloud_rng(4);
  auto cloud_run = [&] {
    for (int c = 0; c < options.clouds; ++c)
      maker.Make(reference.model(), reference.data(), reference.base(), cloud_rng, scene.data(),
                 arm.data());
    return double(options.clouds);
  };

  // Each repeat measures everything back to back, so ratios compare runs seconds apart on a
  // shared, noisy machine; medians over repeats.
  std::vector<double> raw, raw2, v1, v2, rays, embree_rays, clouds, overhead, scaling, raw_scaling,
      cloud_ratio;
  for (int r = 0; r < options.repeats; ++r) {
    const RawStepRates raw_rates = MeasureRawSteps(reference, options.raw_steps, 7 + 2 * r);
    raw.push_back(raw_rates.one);
    raw2.push_back(raw_rates.two);
    v1.push_back(Rate([&] { return vec_run(vec1); }));
    v2.push_back(Rate([&] { return vec_run(vec2); }));
    rays.push_back(Rate(ray_run));
    embree_rays.push_back(Rate(embree_run));
    clouds.push_back(Rate(cloud_run));
    overhead.push_back(raw.back() / v1.back() - 1.0);
    scaling.push_back(v2.back() / v1.back());
    raw_scaling.push_back(raw2.back() / raw.back());
    cloud_ratio.push_back((embree_rays.back() / pixels) / clouds.back());
  }

  return {{"task", task->spec().name},
          {"repeats", options.repeats},
          {"num_envs", options.num_envs},
          {"raw_mj_step_per_s", core::Median(raw)},
          {"vecenv_physics_steps_per_s_1_thread", core::Median(v1)},
          {"vecenv_physics_steps_per_s_2_threads", core::Median(v2)},
          {"vecenv_overhead_vs_raw", core::Median(overhead)},
          {"thread_scaling_2_vs_1", core::Median(scaling)},
          {"raw_mj_step_thread_scaling_2_vs_1", core::Median(raw_scaling)},
          {"thread_scaling_vs_raw_ceiling", core::Median(scaling) / core::Median(raw_scaling)},
          {"raw_mj_ray_per_s", core::Median(rays)},
          {"raw_embree_ray_per_s", core::Median(embree_rays)},
          {"camera", {{"width", k.width}, {"height", k.height}}},
          {"rendered_clouds_per_s_1_core", core::Median(clouds)},
          {"rendered_cloud_time_vs_raw_embree_rays", core::Median(cloud_ratio)}};
}

}  // namespace twinforge::sim
