#include "learn/torch_runtime.h"

#include <dlfcn.h>
#include <malloc.h>
#include <torch/torch.h>
#include <torch/version.h>

#include <cstdlib>
#include <filesystem>

namespace twinforge::learn {

namespace {
template <class Fn>
Fn Symbol(const char* name) {
  return reinterpret_cast<Fn>(::dlsym(RTLD_DEFAULT, name));
}
}  // namespace

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
  return info;
}

std::string TorchVersion() { return TORCH_VERSION; }

int TorchThreads() { return torch::get_num_threads(); }

}  // namespace twinforge::learn
