// LibTorch's math runtime: which BLAS it resolved to, and how many threads it may use.
//
// Debian's LibTorch calls whatever libblas.so.3 the alternatives system points to. The reference
// BLAS is ~14x slower than OpenBLAS for our networks, and OpenBLAS left multi-threaded on a
// 2-core machine that also steps environments is ~20x slower again: every twinforge process pins
// its math to one thread at start-up and parallelises across environments and processes instead.
#pragma once

#include <string>

namespace twinforge::learn {

struct BlasInfo {
  std::string library;  // file that provides sgemm_, e.g. .../openblas-pthread/libblas.so.3
  std::string vendor;   // "openblas", "reference", "mkl", "blis" or "unknown"
  int threads = 0;      // BLAS threads (OpenBLAS only; 0 if unknown)
  std::string kernels;  // the CPU OpenBLAS chose its kernels for, e.g. "SkylakeX" ("" if unknown)
};

// Pins OpenBLAS and LibTorch's intra-op pool to `threads` and exports OPENBLAS_NUM_THREADS for
// child processes. Call once at start-up, before any tensor work.
void PinMathThreads(int threads = 1);

// The OpenBLAS kernels this CPU can run best: "SkylakeX" with AVX-512, "Haswell" with AVX2 and
// FMA, "" with neither.
std::string KernelsForThisCpu();

// OpenBLAS chooses its kernels when it loads, before main(). Debian 12's (0.3.21) does not know
// recent Intel CPUs (Sapphire Rapids, as on this project's machines) and falls back to Prescott's
// SSE3 kernels: matmul ran 26 GFLOP/s where it runs 130 on the AVX-512 ones, PPO updates 3.3x and
// point-cloud BC 2.4-2.8x slower. Where that happened (and OPENBLAS_CORETYPE is not set), this sets
// OPENBLAS_CORETYPE to KernelsForThisCpu() and starts the program again with the same `argv`;
// the new process returns here with the right kernels. Call first thing in main(). If the
// restart fails it returns and the program goes on with the slow kernels (doctor says so).
void RestartWithTheRightBlasKernels(char** argv);

// Whether `blas` is OpenBLAS on Prescott's kernels where this CPU runs better ones.
bool OnSse3Fallback(const BlasInfo& blas);

// Keeps freed large buffers in the heap. A point-cloud batch's activations are ~30 MB, above
// glibc's largest mmap threshold, so every one was mapped, zero-filled and unmapped: BC ran 1.7x
// slower, 40% of it in the kernel. Call once at start-up.
void KeepLargeBuffers();

// The BLAS that sgemm_ resolves to in this process.
BlasInfo QueryBlas();

// LibTorch's version, e.g. "1.13.1", and its intra-op thread count.
std::string TorchVersion();
int TorchThreads();

}  // namespace twinforge::learn
