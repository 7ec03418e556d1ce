#include "samrl/sensing_q.h"

#include <gtest/gtest.h>

#include "learn/torch_runtime.h"
#include "samrl/test_scenes.h"

namespace twinforge::samrl {
namespace {

using testing::Mount;
using testing::OccludedTarget;
using testing::Small;
using testing::VisibleTarget;

double TrueScore(const real2sim::RasterMesh& scene, const OrbitMount& mount, double az, double el) {
  torch::NoGradGuard no_grad;
  return VisibleTarget(
             real2sim::SoftRasterize(scene, Small(),
                                     OrbitPose(mount, torch::tensor({az, el}, torch::kFloat64))))
      .item<double>();
}

// Episodes "succeed" as much as their view shows the target. A Q learned from 200 such views
// (depth, silhouette and the target's mask) predicts held-out returns, and gradient ascent on it
// through the renderer, from the best of a few sampled views, finds a view that shows the target.
TEST(SensingQ, ALearnedQChoosesAViewThatShowsTheTarget) {
  learn::PinMathThreads(1);
  const auto scene = OccludedTarget();
  const OrbitMount mount = Mount();
  core::Rng rng(11);
  std::vector<ViewReturn> samples;
  double best = 0;
  for (int i = 0; i < 200; ++i) {
    const double az = rng.Uniform(mount.min_azimuth, mount.max_azimuth);
    const double el = rng.Uniform(mount.min_elevation, mount.max_elevation);
    torch::NoGradGuard no_grad;
    const auto image = real2sim::SoftRasterize(
        scene, Small(), OrbitPose(mount, torch::tensor({az, el}, torch::kFloat64)));
    const double score = VisibleTarget(image).item<double>();
    best = std::max(best, score);
    samples.push_back({ViewInput(image), torch::Tensor(), score});
  }
  torch::manual_seed(5);
  SensingQNet net(30, 40, 0);
  SensingQOptions options;
  options.steps = 600;
  const SensingQReport fit = FitSensingQ(net, samples, options);
  EXPECT_LT(fit.valid_loss, 0.25 * fit.valid_baseline)
      << "train " << fit.train_loss << " valid " << fit.valid_loss << " baseline "
      << fit.valid_baseline;

  ViewSearchOptions search;
  search.samples = 16;
  search.steps = 40;
  core::Rng pick(3);
  const ViewChoice choice =
      ChooseView(scene, Small(), mount, QScore(net, torch::Tensor()), pick, search);
  EXPECT_EQ(choice.scores.size(), 16u + 41u);
  const double chosen = TrueScore(scene, mount, choice.azimuth, choice.elevation);
  const double fixed = TrueScore(scene, mount, 0.0, 0.4);  // straight over the wall
  EXPECT_LT(fixed, 0.1 * best);
  EXPECT_GT(chosen, 0.8 * best) << "chosen " << chosen << " at az " << choice.azimuth << " el "
                                << choice.elevation << "; best sampled " << best;
}

}  // namespace
}  // namespace twinforge::samrl
