// Seeded random numbers with portable distributions and state snapshots.
//
// Each consumer (an env, a sampler, a trainer) owns its Rng, derived from (seed, stream) so
// results never depend on how work is spread over threads. Distributions are implemented here,
// not taken from <random>, so a seed gives the same numbers with any standard library.
#pragma once

#include <cstdint>
#include <random>
#include <string>
#include <vector>

namespace twinforge::core {

// Mixes a seed and a stream id into one well-spread 64-bit seed (SplitMix64).
uint64_t MixSeed(uint64_t seed, uint64_t stream);

class Rng {
 public:
  explicit Rng(uint64_t seed = 0, uint64_t stream = 0) : engine_(MixSeed(seed, stream)) {}

  uint64_t Bits() { return engine_(); }
  // Uniform in [0, 1).
  double Uniform() { return static_cast<double>(engine_() >> 11) * 0x1.0p-53; }
  // Uniform in [lo, hi).
  double Uniform(double lo, double hi) { return lo + (hi - lo) * Uniform(); }
  // Uniform integer in [0, n). n must be > 0.
  uint64_t Index(uint64_t n);
  // Uniform integer in [lo, hi] (inclusive).
  int64_t Int(int64_t lo, int64_t hi) { return lo + static_cast<int64_t>(Index(hi - lo + 1)); }
  // Standard normal (Box-Muller, one value per call).
  double Normal();
  double Normal(double mean, double stddev) { return mean + stddev * Normal(); }
  bool Bernoulli(double p) { return Uniform() < p; }
  // Fisher-Yates shuffle.
  template <class T>
  void Shuffle(std::vector<T>& items) {
    for (std::size_t i = items.size(); i > 1; --i) std::swap(items[i - 1], items[Index(i)]);
  }
  // A child generator for sub-stream `stream`, independent of this one's future draws.
  Rng Fork(uint64_t stream) { return Rng(Bits(), stream); }

  // The full generator state as text, and back: checkpoints resume exactly.
  std::string Save() const;
  void Load(const std::string& state);

  bool operator==(const Rng& other) const { return engine_ == other.engine_; }

 private:
  std::mt19937_64 engine_;
};

}  // namespace twinforge::core
