#include "real2sim/open3d_info.h"

#include <open3d/Open3D.h>

namespace twinforge::real2sim {

std::string Open3dVersion() { return OPEN3D_VERSION; }

std::string Open3dSelfCheck() {
  try {
    // A flat wall 1 m in front of a 32x24 camera, integrated once, must give a non-empty mesh.
    open3d::geometry::Image depth;
    depth.Prepare(32, 24, 1, 4);
    open3d::geometry::Image color;
    color.Prepare(32, 24, 3, 1);
    for (int v = 0; v < 24; ++v)
      for (int u = 0; u < 32; ++u) *depth.PointerAt<float>(u, v) = 1.0f;
    auto rgbd = open3d::geometry::RGBDImage::CreateFromColorAndDepth(color, depth, 1.0, 3.0, false);
    open3d::camera::PinholeCameraIntrinsic intrinsic(32, 24, 30.0, 30.0, 16.0, 12.0);
    open3d::pipelines::integration::ScalableTSDFVolume volume(
        0.02, 0.08, open3d::pipelines::integration::TSDFVolumeColorType::RGB8);
    volume.Integrate(*rgbd, intrinsic, Eigen::Matrix4d::Identity());
    const auto mesh = volume.ExtractTriangleMesh();
    if (mesh->triangles_.empty()) return "TSDF integration of a test frame produced no mesh";
    return "";
  } catch (const std::exception& e) {
    return e.what();
  }
}

}  // namespace twinforge::real2sim
