#include "sim/geom_distance.h"

#include <gtest/gtest.h>

#include <cmath>
#include <sstream>
#include <string>

#include "sim/model.h"

namespace twinforge::sim {
namespace {

// A flat disc's mesh: eight points round a circle of radius `r` at each of two heights (0 and
// `thick`), centred at (cx, 0) of the mesh's own frame.
std::string DiscVertices(double r, double thick, double cx) {
  std::ostringstream v;
  for (double z : {0.0, thick})
    for (int k = 0; k < 8; ++k)
      v << cx + r * std::cos(k * M_PI / 4) << ' ' << r * std::sin(k * M_PI / 4) << ' ' << z << ' ';
  return v.str();
}

// A scanned pancake's shape: a disc 5 cm in radius, 6 mm thick, on a body turned 30 deg. Its mesh
// is off its body's origin by 10 cm (MuJoCo moves the geom's frame to the mesh's middle); a box
// beside it on the same body.
std::string Scene() {
  return "<mujoco><asset><mesh name='disc' vertex='" + DiscVertices(0.05, 0.006, 0.1) +
         "'/></asset><worldbody><body name='pancake' pos='0.6 0 0.03' euler='0 0 30'>"
         "<geom name='disc' type='mesh' mesh='disc'/>"
         "<geom name='tab' type='box' pos='0.1 0.2 0.003' size='0.01 0.01 0.003'/>"
         "</body></worldbody></mujoco>";
}

TEST(GeomDistance, AMeshIsAsFarAsTheBoxItsVerticesSpan) {
  const ModelPtr model = LoadModelFromText(Scene());
  const DataPtr data = MakeData(model.get());
  mj_forward(model.get(), data.get());
  const mjModel* m = model.get();
  const int body = mj_name2id(m, mjOBJ_BODY, "pancake");
  const int disc = mj_name2id(m, mjOBJ_GEOM, "disc");
  const GeomDistance distance(m);
  // The disc's middle in the world: 10 cm along the body's turned x, 3 mm up from its origin.
  const double yaw = M_PI / 6;
  const Eigen::Vector3d along(std::cos(yaw), std::sin(yaw), 0);
  const Eigen::Vector3d middle = Eigen::Vector3d(0.6, 0, 0.033) + 0.1 * along;
  const Eigen::Map<const Eigen::Matrix<double, 3, 3, Eigen::RowMajor>> rotation(data->geom_xmat +
                                                                                9 * disc);
  const Eigen::Map<const Eigen::Vector3d> position(data->geom_xpos + 3 * disc);
  const auto to_disc = [&](const Eigen::Vector3d& p) {
    return distance.ToGeom(m, disc, rotation, position, p);
  };
  // Inside, 4 cm over the middle (its bounding sphere, 5 cm round, held that too), 6 cm out
  // along its own x (1 cm past the points on the circle) and 1.3 cm under the middle (1 cm under
  // its underside).
  EXPECT_NEAR(to_disc(middle), 0.0, 1e-9);
  EXPECT_NEAR(to_disc(middle + Eigen::Vector3d(0, 0, 0.04)), 0.037, 1e-6);
  EXPECT_NEAR(to_disc(middle + 0.06 * along), 0.01, 1e-6);
  EXPECT_NEAR(to_disc(middle + Eigen::Vector3d(0, 0, -0.013)), 0.01, 1e-6);
  // The body: the nearer of the disc and the box, where the data has them.
  const Eigen::Vector3d across(-std::sin(yaw), std::cos(yaw), 0);
  const Eigen::Vector3d tab = Eigen::Vector3d(0.6, 0, 0.033) + 0.1 * along + 0.2 * across;
  EXPECT_NEAR(distance.ToBody(m, data.get(), body, tab + 0.015 * across), 0.005, 1e-6);
  EXPECT_NEAR(distance.ToBody(m, data.get(), body, middle + Eigen::Vector3d(0, 0, 0.02)), 0.017,
              1e-6);
}

}  // namespace
}  // namespace twinforge::sim
