// A pinhole camera's intrinsics (pixels), shared by the sim's cameras and the scan files.
#pragma once

namespace twinforge::core {

struct PinholeIntrinsics {
  int width = 80, height = 60;
  double fx = 0, fy = 0, cx = 0, cy = 0;
  bool operator==(const PinholeIntrinsics&) const = default;
};

}  // namespace twinforge::core
