// How fast learning's math runs on this machine, against the machine's own matmul peak measured
// in the same process: PPO + BC updates on RialTo's teacher shape and point-cloud BC steps.
#pragma once

#include <nlohmann/json.hpp>

namespace twinforge::learn {

struct LearnBenchOptions {
  int repeats = 5;     // runs per measurement; medians are reported
  int state_dim = 32;  // RialTo's teacher: obs 32 -> [256, 256] -> 14 logits + value head
  int minibatch = 4096;
  int cloud_batch = 64;    // DP3-style encoder
  int cloud_points = 512;  // points per cloud (the policies' default)
};

// The machine's matmul peak in GFLOP/s: the median of `repeats` runs of four square 1024
// single-precision products, the best case for the BLAS.
double MatmulPeakGflops(int repeats);

// FLOPs of one PPO training sample through the policy and value MLPs (state -> [hidden, hidden]
// -> actions, and -> 1): the forward pass and a backward pass of about twice the forward.
double PpoSampleFlops(int state_dim, int hidden, int action_dim);

// JSON: matmul peak (GFLOP/s), PPO update samples/s and GFLOP/s (and as a share of the peak),
// point-cloud BC clouds/s, with the BLAS in use.
nlohmann::json RunLearnBench(const LearnBenchOptions& options);

}  // namespace twinforge::learn
