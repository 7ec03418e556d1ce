#include "sim/geom_scene.h"

#include <array>
#include <cmath>
#include <limits>
#include <string>

#include "core/error.h"
#include "sim/embree_ray.h"

namespace twinforge::sim {

namespace {

constexpr int kAround = 32;          // segments around a surface of revolution
constexpr int kProfile = 16;         // segments along a half circle of a sphere's profile
constexpr float kPlaneHalf = 20.0f;  // an infinite plane (size 0) as a 40 m square

// A surface of revolution about z through the (radius, z) profile points, bottom to top.
void Lathe(const std::vector<std::array<float, 2>>& profile, TriangleMesh& mesh) {
  const unsigned first = static_cast<unsigned>(mesh.vertices.size() / 3);
  for (const auto& [r, z] : profile)
    for (int k = 0; k < kAround; ++k) {
      const double phi = 2.0 * M_PI * k / kAround;
      mesh.vertices.insert(mesh.vertices.end(), {static_cast<float>(r * std::cos(phi)),
                                                 static_cast<float>(r * std::sin(phi)), z});
    }
  for (unsigned j = 0; j + 1 < profile.size(); ++j)
    for (unsigned k = 0; k < kAround; ++k) {
      const unsigned a = first + j * kAround + k, b = first + j * kAround + (k + 1) % kAround;
      const unsigned c = a + kAround, d = b + kAround;
      mesh.triangles.insert(mesh.triangles.end(), {a, b, d, a, d, c});
    }
}

// Half-circle profile of radius r, from angle `from` to `to` (radians from the equator),
// centred at height z0.
void Arc(std::vector<std::array<float, 2>>& profile, double r, double z0, double from, double to,
         int segments) {
  for (int i = 0; i <= segments; ++i) {
    const double a = from + (to - from) * i / segments;
    profile.push_back(
        {static_cast<float>(r * std::cos(a)), static_cast<float>(z0 + r * std::sin(a))});
  }
}

void Box(TriangleMesh& mesh) {
  for (int i = 0; i < 8; ++i)
    mesh.vertices.insert(mesh.vertices.end(),
                         {i & 1 ? 1.0f : -1.0f, i & 2 ? 1.0f : -1.0f, i & 4 ? 1.0f : -1.0f});
  // Two triangles per face; corners indexed by their (x, y, z) sign bits.
  mesh.triangles = {0, 2, 3, 0, 3, 1, 4, 5, 7, 4, 7, 6, 0, 1, 5, 0, 5, 4,
                    2, 6, 7, 2, 7, 3, 0, 4, 6, 0, 6, 2, 1, 3, 7, 1, 7, 5};
}

}  // namespace

TriangleMesh TessellateGeom(const mjModel* m, int g) {
  TriangleMesh mesh;
  const mjtNum* size = m->geom_size + 3 * g;
  std::vector<std::array<float, 2>> profile;
  switch (m->geom_type[g]) {
    case mjGEOM_PLANE:
      mesh.vertices = {-1, -1, 0, 1, -1, 0, 1, 1, 0, -1, 1, 0};
      mesh.triangles = {0, 1, 2, 0, 2, 3};
      mesh.unit = true;
      break;
    case mjGEOM_BOX:
      Box(mesh);
      mesh.unit = true;
      break;
    case mjGEOM_SPHERE:
    case mjGEOM_ELLIPSOID:
      Arc(profile, 1.0, 0.0, -M_PI / 2, M_PI / 2, kProfile);
      Lathe(profile, mesh);
      mesh.unit = true;
      break;
    case mjGEOM_CYLINDER:
      profile = {{0, -1}, {1, -1}, {1, 1}, {0, 1}};
      Lathe(profile, mesh);
      mesh.unit = true;
      break;
    case mjGEOM_CAPSULE:  // hemispheres do not scale: tessellated at the model's size
      Arc(profile, size[0], -size[1], -M_PI / 2, 0.0, kProfile / 2);
      Arc(profile, size[0], size[1], 0.0, M_PI / 2, kProfile / 2);
      Lathe(profile, mesh);
      break;
    case mjGEOM_MESH: {
      const int id = m->geom_dataid[g];
      mesh.vertices.assign(m->mesh_vert + 3 * m->mesh_vertadr[id],
                           m->mesh_vert + 3 * (m->mesh_vertadr[id] + m->mesh_vertnum[id]));
      const int* faces = m->mesh_face + 3 * m->mesh_faceadr[id];
      mesh.triangles.assign(faces, faces + 3 * m->mesh_facenum[id]);
      break;
    }
    default:  // height fields: not used by twinforge scenes
      break;
  }
  return mesh;
}

struct GeomScene::Embree {
  RTCDevice device = nullptr;
  RTCScene top = nullptr;
  std::vector<RTCScene> shapes;
  std::vector<RTCGeometry> instances;
  ~Embree() {
    for (RTCScene s : shapes) rtcReleaseScene(s);
    if (top) rtcReleaseScene(top);
    if (device) rtcReleaseDevice(device);
  }
};

GeomScene::GeomScene(const mjModel* m) : embree_(std::make_unique<Embree>()) {
  // One build thread: twinforge parallelises across environments, not inside one.
  embree_->device = rtcNewDevice("threads=1,set_affinity=0");
  if (!embree_->device)
    throw core::Error("Embree: could not create a device (error " +
                      std::to_string(rtcGetDeviceError(nullptr)) + ")");
  RTCDevice device = embree_->device;
  embree_->top = rtcNewScene(device);
  rtcSetSceneFlags(embree_->top, RTC_SCENE_FLAG_DYNAMIC);
  rtcSetSceneBuildQuality(embree_->top, RTC_BUILD_QUALITY_LOW);
  for (int g = 0; g < m->ngeom; ++g) {
    const TriangleMesh mesh = TessellateGeom(m, g);
    if (mesh.triangles.empty()) continue;
    RTCScene shape = TriangleScene(device, mesh.vertices, mesh.triangles);
    embree_->shapes.push_back(shape);

    RTCGeometry instance = rtcNewGeometry(device, RTC_GEOMETRY_TYPE_INSTANCE);
    rtcSetGeometryInstancedScene(instance, shape);
    rtcSetGeometryTimeStepCount(instance, 1);
    const unsigned id = rtcAttachGeometry(embree_->top, instance);
    rtcReleaseGeometry(instance);  // the scene holds it
    if (id != geom_of_instance_.size()) throw core::Error("Embree: unexpected instance id");
    embree_->instances.push_back(instance);
    geom_of_instance_.push_back(g);
    unit_shape_.push_back(mesh.unit);
    enabled_.push_back(1);
  }
}

GeomScene::~GeomScene() = default;
GeomScene::GeomScene(GeomScene&&) noexcept = default;
GeomScene& GeomScene::operator=(GeomScene&&) noexcept = default;

void GeomScene::Update(const mjModel* m, const mjData* d, unsigned hidden_groups) {
  for (std::size_t i = 0; i < geom_of_instance_.size(); ++i) {
    const int g = geom_of_instance_[i];
    RTCGeometry instance = embree_->instances[i];
    const bool enable = GeomRgba(m, g)[3] > 0 && !((hidden_groups >> m->geom_group[g]) & 1u);
    if (enable != static_cast<bool>(enabled_[i])) {
      enable ? rtcEnableGeometry(instance) : rtcDisableGeometry(instance);
      enabled_[i] = enable;
    }
    if (!enable) continue;
    // Column-major 3x4: rotation (times the unit shape's scale) and translation.
    std::array<double, 3> scale{1, 1, 1};
    if (unit_shape_[i]) scale = UnitShapeScale(m, g);
    const mjtNum* r = d->geom_xmat + 9 * g;  // row-major
    float xfm[12];
    for (int col = 0; col < 3; ++col)
      for (int row = 0; row < 3; ++row) xfm[3 * col + row] = r[3 * row + col] * scale[col];
    for (int row = 0; row < 3; ++row) xfm[9 + row] = d->geom_xpos[3 * g + row];
    rtcSetGeometryTransform(instance, 0, RTC_FORMAT_FLOAT3X4_COLUMN_MAJOR, xfm);
    rtcCommitGeometry(instance);
  }
  rtcCommitScene(embree_->top);
}

GeomScene::Hit GeomScene::Cast(const float origin[3], const float direction[3]) const {
  const RTCRayHit rh = FirstHit(embree_->top, origin, direction);
  if (rh.hit.geomID == RTC_INVALID_GEOMETRY_ID) return {};
  return {rh.ray.tfar, geom_of_instance_[rh.hit.instID[0]]};
}

RTCScene TriangleScene(RTCDevice device, const std::vector<float>& vertices,
                       const std::vector<unsigned>& triangles, RTCSceneFlags flags) {
  RTCGeometry tris = rtcNewGeometry(device, RTC_GEOMETRY_TYPE_TRIANGLE);
  auto* v = static_cast<float*>(rtcSetNewGeometryBuffer(
      tris, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3, 3 * sizeof(float), vertices.size() / 3));
  std::copy(vertices.begin(), vertices.end(), v);
  auto* t = static_cast<unsigned*>(rtcSetNewGeometryBuffer(tris, RTC_BUFFER_TYPE_INDEX, 0,
                                                           RTC_FORMAT_UINT3, 3 * sizeof(unsigned),
                                                           triangles.size() / 3));
  std::copy(triangles.begin(), triangles.end(), t);
  rtcCommitGeometry(tris);
  RTCScene scene = rtcNewScene(device);
  rtcSetSceneFlags(scene, flags);
  rtcAttachGeometry(scene, tris);
  rtcReleaseGeometry(tris);  // the scene holds it
  rtcCommitScene(scene);
  return scene;
}

RTCRayHit FirstHit(RTCScene scene, const float origin[3], const float direction[3]) {
  RTCIntersectContext context;
  rtcInitIntersectContext(&context);
  RTCRayHit rh;
  rh.ray.org_x = origin[0];
  rh.ray.org_y = origin[1];
  rh.ray.org_z = origin[2];
  rh.ray.dir_x = direction[0];
  rh.ray.dir_y = direction[1];
  rh.ray.dir_z = direction[2];
  rh.ray.tnear = 0.0f;
  rh.ray.tfar = std::numeric_limits<float>::infinity();
  rh.ray.time = 0.0f;
  rh.ray.mask = ~0u;
  rh.ray.id = 0;
  rh.ray.flags = 0;
  rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
  rh.hit.instID[0] = RTC_INVALID_GEOMETRY_ID;
  rtcIntersect1(scene, &context, &rh);
  return rh;
}

std::array<double, 3> UnitShapeScale(const mjModel* m, int g) {
  const mjtNum* s = m->geom_size + 3 * g;
  switch (m->geom_type[g]) {
    case mjGEOM_PLANE:
      return {s[0] > 0 ? s[0] : kPlaneHalf, s[1] > 0 ? s[1] : kPlaneHalf, 1};
    case mjGEOM_SPHERE:
      return {s[0], s[0], s[0]};
    case mjGEOM_CYLINDER:
      return {s[0], s[0], s[1]};
    default:  // box, ellipsoid: half-sizes per axis
      return {s[0], s[1], s[2]};
  }
}

}  // namespace twinforge::sim
