// Small measuring helpers shared by benchmarks and long-running stages.
#pragma once

#include <algorithm>
#include <chrono>
#include <vector>

namespace twinforge::core {

using Clock = std::chrono::steady_clock;

// Wall-clock seconds from `start` to now.
inline double SecondsSince(Clock::time_point start) {
  return std::chrono::duration<double>(Clock::now() - start).count();
}

// Wall-clock seconds `work()` takes.
template <class Work>
double Seconds(Work&& work) {
  const auto start = Clock::now();
  work();
  return SecondsSince(start);
}

// The median of `values` (the upper one of an even count); 0 when empty. Benchmarks report it:
// shared machines are noisy.
inline double Median(std::vector<double> values) {
  if (values.empty()) return 0;
  std::nth_element(values.begin(), values.begin() + values.size() / 2, values.end());
  return values[values.size() / 2];
}

}  // namespace twinforge::core
