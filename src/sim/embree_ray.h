// Embree's ray queries as twinforge uses them: the depth renderer (GeomScene) and
// real2sim::SurfaceQuery. Brings in Embree's header: include it from .cpp files only.
#pragma once

#include <embree3/rtcore.h>

#include <vector>

namespace twinforge::sim {

// A committed scene of one triangle mesh (xyz per vertex, three vertex indices per triangle).
RTCScene TriangleScene(RTCDevice device, const std::vector<float>& vertices,
                       const std::vector<unsigned>& triangles,
                       RTCSceneFlags flags = RTC_SCENE_FLAG_NONE);

// The ray from `origin` along the unit `direction` cast into a committed `scene`: its
// hit.geomID is RTC_INVALID_GEOMETRY_ID where it meets nothing, else its ray.tfar says how far it
// went.
RTCRayHit FirstHit(RTCScene scene, const float origin[3], const float direction[3]);

}  // namespace twinforge::sim
