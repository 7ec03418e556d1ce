// Test helpers for the pipeline's reality-facing stages: the proxy reality behind a counter, and
// untrained policies written to files.
#pragma once

#include <filesystem>
#include <string>
#include <vector>

#include "learn/policy_net.h"
#include "reality/proxy_reality.h"

namespace twinforge::pipeline::testing {

// The proxy reality behind a counter of resets, with or without its success oracle.
class Counted : public reality::Robot {
 public:
  Counted(reality::ProxyReality& inner, bool oracle) : inner_(inner), oracle_(oracle) {}
  reality::RobotInfo Info() override {
    reality::RobotInfo info = inner_.Info();
    info.has_success_oracle = oracle_;
    return info;
  }
  reality::Observation Observe(bool with_frames) override { return inner_.Observe(with_frames); }
  void SendTargets(const sim::JointTargets& targets) override {
    ++actions;
    sent.push_back(targets);
    inner_.SendTargets(targets);
  }
  reality::Observation Reset(const reality::ResetRequest& request) override {
    ++resets;
    return inner_.Reset(request);
  }
  reality::SuccessAnswer QuerySuccess() override {
    return oracle_ ? inner_.QuerySuccess() : reality::SuccessAnswer::kUnknown;
  }
  int resets = 0, actions = 0;
  std::vector<sim::JointTargets> sent;

 private:
  reality::ProxyReality& inner_;
  bool oracle_;
};

inline std::filesystem::path Policy(const std::filesystem::path& dir, int points, int seed) {
  learn::PolicyConfig config;
  if (points > 0) config.points = points;
  if (points == 0) {
    config.point_features = 0;
    config.proprio_dim = 17;
  }
  torch::manual_seed(seed);
  learn::PolicyNet net(config);
  const auto path = dir / ("policy" + std::to_string(points) + "_" + std::to_string(seed) + ".pt");
  learn::SavePolicy(net, path);
  return path;
}

}  // namespace twinforge::pipeline::testing
