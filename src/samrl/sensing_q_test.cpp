#include "samrl/sensing_q.h"

#include <gtest/gtest.h>

#include "core/error.h"
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

// 200 views from poses drawn uniformly on the mount, as Q reads them, each with how much of the
// target it shows (VisibleTarget), and the most any shows.
struct RandomViews {
  RandomViews(const real2sim::RasterMesh& scene, const OrbitMount& mount, uint64_t seed) {
    core::Rng rng(seed);
    torch::NoGradGuard no_grad;
    for (int i = 0; i < 200; ++i) {
      const double az = rng.Uniform(mount.min_azimuth, mount.max_azimuth);
      const double el = rng.Uniform(mount.min_elevation, mount.max_elevation);
      const auto image = real2sim::SoftRasterize(
          scene, Small(), OrbitPose(mount, torch::tensor({az, el}, torch::kFloat64)));
      const double shown = VisibleTarget(image).item<double>();
      best = std::max(best, shown);
      views.emplace_back(ViewInput(image), shown);
    }
  }
  std::vector<std::pair<torch::Tensor, double>> views;
  double best = 0;
};

// Episodes "succeed" as much as their view shows the target. A Q learned from 200 such views
// (depth, silhouette and the target's mask) predicts held-out returns, and gradient ascent on it
// through the renderer, from the best of a few sampled views, finds a view that shows the target.
TEST(SensingQ, ALearnedQChoosesAViewThatShowsTheTarget) {
  learn::PinMathThreads(1);
  const auto scene = OccludedTarget();
  const OrbitMount mount = Mount();
  const RandomViews views(scene, mount, 11);
  std::vector<ViewReturn> samples;
  for (const auto& [view, shown] : views.views) samples.push_back({view, torch::Tensor(), shown});
  const double best = views.best;
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

// Q reads the actor's plan too. Here the returns of step 0 follow how much of the target a view
// shows, and those of step 1 the opposite (as if, with the target in hand, a view of it were in
// the way). Fitted to both, Q at a look chooses a view that shows the target for step 0 and one
// that hides it for step 1: the plan in the context, not the view alone, decides.
TEST(SensingQ, AQOfThePlanChoosesAViewForTheStepTheActorDoesNext) {
  learn::PinMathThreads(1);
  const auto scene = OccludedTarget();
  const OrbitMount mount = Mount();
  const RandomViews views(scene, mount, 12);
  const double best = views.best;
  std::vector<ViewReturn> samples;
  for (int i = 0; i < int(views.views.size()); ++i) {
    const auto& [view, shown] = views.views[i];
    samples.push_back({view, PlanInput(0, 2), shown / best, i});
    samples.push_back({view, PlanInput(1, 2), 1 - shown / best, i});
  }
  torch::manual_seed(5);
  SensingQNet net(30, 40, 2);
  SensingQOptions options;
  options.steps = 600;
  const SensingQReport fit = FitSensingQ(net, samples, options);
  EXPECT_LT(fit.valid_loss, 0.25 * fit.valid_baseline);

  const reality::Observation observation;
  const LookScore score = QLookScore(net);
  ViewSearchOptions search;
  search.samples = 16;
  search.steps = 40;
  double shown[2];
  for (int step = 0; step < 2; ++step) {
    core::Rng pick(3);
    const ViewChoice choice =
        ChooseView(scene, Small(), mount, score({observation, {}, "", step, 2}), pick, search);
    shown[step] = TrueScore(scene, mount, choice.azimuth, choice.elevation) / best;
  }
  EXPECT_GT(shown[0], 0.8) << "step 0's view shows the target";
  EXPECT_LT(shown[1], 0.2) << "step 1's view hides it";
  EXPECT_THROW(PlanInput(-1, 2), core::Error);
}

}  // namespace
}  // namespace twinforge::samrl
