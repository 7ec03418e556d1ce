#include "app/doctor.h"

#include <H5public.h>

#include <filesystem>
#include <ostream>
#include <string>
#include <vector>

#include "learn/torch_runtime.h"
#include "real2sim/open3d_info.h"
#include "sim/model.h"

namespace twinforge::app {

namespace {
struct Check {
  std::string name;
  bool ok;
  std::string detail;
  std::string fix;
};
}  // namespace

int RunDoctor(std::ostream& out) {
  std::vector<Check> checks;
  const auto blas = learn::QueryBlas();
  unsigned h5_major = 0, h5_minor = 0, h5_release = 0;
  H5get_libversion(&h5_major, &h5_minor, &h5_release);

  out << "twinforge doctor\n";
  out << "  MuJoCo   " << sim::MujocoVersion() << "\n";
  out << "  LibTorch " << learn::TorchVersion() << " (intra-op threads " << learn::TorchThreads()
      << ")\n";
  out << "  Open3D   " << real2sim::Open3dVersion() << "\n";
  out << "  HDF5     " << h5_major << "." << h5_minor << "." << h5_release << "\n";
  out << "  BLAS     " << blas.vendor << " at "
      << (blas.library.empty() ? "<not found>" : blas.library) << " (threads " << blas.threads
      << ", kernels " << (blas.kernels.empty() ? "unknown" : blas.kernels) << ")\n";

  checks.push_back({"MuJoCo >= 2.2", mj_version() >= 220, sim::MujocoVersion(),
                    "install Debian's libmujoco-dev (scripts/setup.sh)"});
  checks.push_back({"BLAS is OpenBLAS", blas.vendor == "openblas",
                    blas.vendor + " (" + blas.library + ")",
                    blas.vendor == "reference"
                        ? "the reference BLAS is ~14x slower for our networks: run "
                          "'apt-get install libopenblas0-pthread && update-alternatives --set "
                          "libblas.so.3-x86_64-linux-gnu "
                          "/usr/lib/x86_64-linux-gnu/openblas-pthread/libblas.so.3' "
                          "(scripts/setup.sh does both), and unset LD_LIBRARY_PATH overrides"
                        : "install libopenblas0-pthread (scripts/setup.sh)"});
  checks.push_back({"BLAS pinned to 1 thread", blas.vendor != "openblas" || blas.threads == 1,
                    std::to_string(blas.threads) + " threads",
                    "twinforge pins BLAS at start-up; something reset it (OPENBLAS_NUM_THREADS?)"});
  // OpenBLAS 0.3.21 falls back to Prescott's SSE3 kernels on CPUs it does not know; twinforge
  // restarts itself with OPENBLAS_CORETYPE set (learn/torch_runtime.h).
  const std::string cpu = learn::KernelsForThisCpu();
  checks.push_back({"BLAS kernels fit the CPU", !learn::OnSse3Fallback(blas),
                    (blas.kernels.empty() ? "unknown" : blas.kernels) + " kernels" +
                        (cpu.empty() ? " (this CPU has no AVX2)" : ", the CPU runs " + cpu + "'s"),
                    "OpenBLAS fell back to its SSE3 kernels (~3x slower for our networks): "
                    "unset OPENBLAS_CORETYPE, or set it to " +
                        cpu});
  const std::string o3d = real2sim::Open3dSelfCheck();
  checks.push_back({"Open3D TSDF works", o3d.empty(), o3d.empty() ? "ok" : o3d,
                    "reinstall libopen3d-dev (scripts/setup.sh)"});
  const std::filesystem::path assets = TWINFORGE_ASSETS_DIR;
  checks.push_back({"assets directory", std::filesystem::is_directory(assets), assets.string(),
                    "run twinforge from its build tree, or set TWINFORGE_ASSETS"});

  int failed = 0;
  out << "checks\n";
  for (const auto& c : checks) {
    out << "  [" << (c.ok ? " ok " : "FAIL") << "] " << c.name << ": " << c.detail << "\n";
    if (!c.ok) {
      out << "         fix: " << c.fix << "\n";
      ++failed;
    }
  }
  out << (failed ? std::to_string(failed) + " check(s) failed\n" : "all checks passed\n");
  return failed ? 1 : 0;
}

}  // namespace twinforge::app
