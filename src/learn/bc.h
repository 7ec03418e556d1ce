// Behaviour cloning on point clouds and proprioception: RialTo's first stage, on the ~15 demos
// recorded on the robot (`demos record`, core/dataset.h layout).
#pragma once

#include <cstdint>
#include <filesystem>
#include <string>

#include "core/progress.h"
#include "core/rng.h"

namespace twinforge::learn {

// How one observation's points become the policy's input: `n` rows of (x, y, z, is_arm) drawn
// from the scene's and the arm's points. Training augments as RialTo does: a random share in
// [drop_min, drop_max] of the points dropped, then each jittered by Gaussian noise. The points
// are drawn as sim::ResamplePoints draws them: each once before any twice.
struct PointSampling {
  static constexpr int kMinN = 16, kMaxN = 8192;  // the counts a policy may be given
  int n = 512;
  double drop_min = 0.1, drop_max = 0.3;
  double jitter = 0.002;  // m
};
void SamplePoints(const float* scene, int scene_n, const float* arm, int arm_n,
                  const PointSampling& sampling, bool augment, core::Rng& rng, float* out);

struct BcOptions {
  PointSampling sampling;
  int hidden = 256;
  int max_epochs = 300;
  int patience = 30;  // epochs without a better validation loss before stopping
  int batch = 64;
  double learning_rate = 1e-3;
  uint64_t seed = 1;
  int threads = 2;  // the gradient's shards run side by side; the result is the same with 1
};

struct BcReport {
  int train_samples = 0, valid_samples = 0;
  int epochs = 0;      // run
  int best_epoch = 0;  // whose weights were kept
  double best_valid_loss = 0;
  double final_train_loss = 0;
  double valid_accuracy = 0;  // discrete: argmax == demo action, on the validation steps
  double valid_mse = 0;       // continuous: of the mean action
  double seconds = 0;
  std::filesystem::path curve;  // CSV: epoch, train_loss, valid_loss, valid_metric
};

// Trains on `demos` (train/valid split from its mask; with no valid mask, every fifth demo is
// held out) and writes the best policy (by validation loss) to `out`, the curve beside it.
// Stops after `patience` epochs without improvement or at `max_epochs`.
BcReport TrainBc(const std::filesystem::path& demos, const std::filesystem::path& out,
                 const BcOptions& options, core::Progress* progress = nullptr);

}  // namespace twinforge::learn
