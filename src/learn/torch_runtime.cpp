#include "learn/torch_runtime.h"

#include <dlfcn.h>
#include <malloc.h>
#include <torch/torch.h>
#include <torch/version.h>
#include <unistd.h>

#include <algorithm>
#include <cctype>
#include <cstdlib>
#include <filesystem>

namespace twinforge::learn {

namespace {
template <class Fn>
Fn Symbol(const char* name) {
  return reinterpret_cast<Fn>(::dlsym(RTLD_DEFAULT, name));
}
}  // namespace

std::string KernelsForThisCpu() {
  __builtin_cpu_init();
  if (__builtin_cpu_supports("avx512f") && __builtin_cpu_supports("avx512bw") &&
      __builtin_cpu_supports("avx512vl") && __builtin_cpu_supports("avx512dq") &&
      __builtin_cpu_supports("avx512cd"))
    return "SkylakeX";
  if (__builtin_cpu_supports("avx2") && __builtin_cpu_supports("fma")) return "Haswell";
  return "";
}

bool OnSse3Fallback(const BlasInfo& blas) {
  std::string kernels = blas.kernels;
  std::transform(kernels.begin(), kernels.end(), kernels.begin(),
                 [](unsigned char c) { return std::tolower(c); });
  return blas.vendor == "openblas" && kernels == "prescott" && !KernelsForThisCpu().empty();
}

void RestartWithTheRightBlasKernels(char** argv) {
  if (std::getenv("OPENBLAS_CORETYPE")) return;  // chosen by the user, or by the restart
  if (!OnSse3Fallback(QueryBlas())) return;
  ::setenv("OPENBLAS_CORETYPE", KernelsForThisCpu().c_str(), 1);
  ::execv("/proc/self/exe", argv);
}

void KeepLargeBuffers() {
  mallopt(M_MMAP_THRESHOLD, 256 << 20);
  mallopt(M_TRIM_THRESHOLD, 1 << 30);
  mallopt(M_TOP_PAD, 64 << 20);
}

void PinMathThreads(int threads) {
  const std::string text = std::to_string(threads);
  ::setenv("OPENBLAS_NUM_THREADS", text.c_str(), 1);
  ::setenv("OMP_NUM_THREADS", text.c_str(), 1);
  if (auto set = Symbol<void (*)(int)>("openblas_set_num_threads")) set(threads);
  torch::set_num_threads(threads);
  // The inter-op pool can be sized only before its first use; later calls keep its size.
  try {
    torch::set_num_interop_threads(threads);
  } catch (const c10::Error&) {
  }
}

BlasInfo QueryBlas() {
  BlasInfo info;
  void* sgemm = ::dlsym(RTLD_DEFAULT, "sgemm_");
  Dl_info where{};
  if (sgemm && ::dladdr(sgemm, &where) && where.dli_fname) {
    std::error_code ec;
    const auto real = std::filesystem::canonical(where.dli_fname, ec);
    info.library = ec ? where.dli_fname : real.string();
  }
  const auto has = [&](const char* s) { return info.library.find(s) != std::string::npos; };
  if (has("openblas"))
    info.vendor = "openblas";
  else if (has("/blas/"))
    info.vendor = "reference";
  else if (has("mkl"))
    info.vendor = "mkl";
  else if (has("blis"))
    info.vendor = "blis";
  else
    info.vendor = "unknown";
  if (auto get = Symbol<int (*)()>("openblas_get_num_threads")) info.threads = get();
  if (auto core = Symbol<char* (*)()>("openblas_get_corename"))
    if (const char* name = core()) info.kernels = name;
  return info;
}

std::string TorchVersion() { return TORCH_VERSION; }

int TorchThreads() { return torch::get_num_threads(); }

}  // namespace twinforge::learn
