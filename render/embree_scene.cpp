#include "embree_scene.h"

#include <bit>
#include <cmath>
#include <mutex>
#include <new>
#include <string>

#include "core/error.h"

namespace spadgen::render {
namespace {

// Embree reports errors through a C callback; throwing through Embree's frames is undefined, so the
// callback records the first message and the caller turns it into spadgen::Error after the call.
struct ErrorSink {
  std::mutex mutex;
  std::string message;
};

void on_embree_error(void* user, RTCError code, const char* str) {
  auto* sink = static_cast<ErrorSink*>(user);
  std::lock_guard<std::mutex> lock(sink->mutex);
  if (sink->message.empty())
    sink->message = "Embree error " + std::to_string(static_cast<int>(code)) + ": " + (str ? str : "");
}

ErrorSink& error_sink() {
  static ErrorSink sink;
  return sink;
}

void check(RTCDevice device, const char* what) {
  ErrorSink& sink = error_sink();
  std::string message;
  {
    std::lock_guard<std::mutex> lock(sink.mutex);
    message.swap(sink.message);
  }
  const RTCError code = device ? rtcGetDeviceError(device) : RTC_ERROR_UNKNOWN;
  if (code == RTC_ERROR_OUT_OF_MEMORY) throw std::bad_alloc();  // (the program's out-of-memory message)
  if (message.empty() && code != RTC_ERROR_NONE) message = "Embree error " + std::to_string(static_cast<int>(code));
  if (!message.empty()) throw Error(std::string("while ") + what + ": " + message);
}

// Ray direction . geometric normal of hit i: negative when the ray meets the front side.
float facing(const RTCFilterFunctionNArguments* args, unsigned i) {
  return RTCRayN_dir_x(args->ray, args->N, i) * RTCHitN_Ng_x(args->hit, args->N, i) +
         RTCRayN_dir_y(args->ray, args->N, i) * RTCHitN_Ng_y(args->hit, args->N, i) +
         RTCRayN_dir_z(args->ray, args->N, i) * RTCHitN_Ng_z(args->hit, args->N, i);
}

// glTF's doubleSided = false means back-face culling: a single-sided, non-transmissive surface does not
// exist seen from behind. Embree's Ng = (v1 - v0) x (v2 - v0), the glTF front side for counter-clockwise
// triangles. "Seen" is along the light's way: a camera or bounce ray looks from its origin (the surface is
// culled when the ray meets its back); a ray towards a light (every occluded ray, and intersect rays with
// toward_light; both carry kTowardLight in their id) stands for light coming the other way, which meets
// the surface from the other side (culled when the ray meets its front), as the light itself sees the scene.
void cull_back_faces(const RTCFilterFunctionNArguments* args) {
  for (unsigned i = 0; i < args->N; ++i) {
    if (args->valid[i] == 0) continue;
    const float d = facing(args, i);
    const bool to_light = (RTCRayN_id(args->ray, args->N, i) & kTowardLight) != 0;
    if (to_light ? d < 0.0f : d > 0.0f) args->valid[i] = 0;
  }
}

}  // namespace

EmbreeScene::EmbreeScene(const scenes::Scene& scene) {
  device_ = rtcNewDevice(nullptr);
  if (!device_) {
    // (error 4, the memory for its threads' arenas: "could not create the Embree device (error 4)" under ulimit -v)
    const RTCError code = rtcGetDeviceError(nullptr);
    if (code == RTC_ERROR_OUT_OF_MEMORY) throw std::bad_alloc();
    throw Error("could not create the Embree device (Embree error " + std::to_string(static_cast<int>(code)) + ")");
  }
  rtcSetDeviceErrorFunction(device_, on_embree_error, &error_sink());
  scene_ = rtcNewScene(device_);
  rtcSetSceneBuildQuality(scene_, RTC_BUILD_QUALITY_HIGH);
  rtcSetSceneFlags(scene_, RTC_SCENE_FLAG_ROBUST);
  check(device_, "creating the Embree scene");

  vertices_.resize(scene.meshes.size());
  for (size_t m = 0; m < scene.meshes.size(); ++m) {
    const scenes::Mesh& mesh = scene.meshes[m];
    if (mesh.triangle_count() == 0 || mesh.positions.empty()) continue;
    for (uint32_t index : mesh.indices)
      if (index >= mesh.positions.size())
        throw Error("mesh '" + mesh.name + "': index " + std::to_string(index) + " is past its " +
                    std::to_string(mesh.positions.size()) + " vertices");
    std::vector<float>& v = vertices_[m];
    v.resize(mesh.positions.size() * 3 + 1, 0.0f);
    for (size_t i = 0; i < mesh.positions.size(); ++i)
      for (int c = 0; c < 3; ++c) v[3 * i + c] = mesh.positions[i][c];

    RTCGeometry geom = rtcNewGeometry(device_, RTC_GEOMETRY_TYPE_TRIANGLE);
    rtcSetSharedGeometryBuffer(geom, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3, v.data(), 0,
                               3 * sizeof(float), mesh.positions.size());
    rtcSetSharedGeometryBuffer(geom, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3, mesh.indices.data(), 0,
                               3 * sizeof(uint32_t), mesh.triangle_count());
    const scenes::Material* mat =
        (mesh.material >= 0 && static_cast<size_t>(mesh.material) < scene.materials.size())
            ? &scene.materials[static_cast<size_t>(mesh.material)]
            : nullptr;
    // The glTF default material is single-sided.
    const bool single_sided = mat ? (!mat->double_sided && !mat->transmissive()) : true;
    if (single_sided) {
      rtcSetGeometryIntersectFilterFunction(geom, cull_back_faces);
      rtcSetGeometryOccludedFilterFunction(geom, cull_back_faces);
    }
    rtcCommitGeometry(geom);
    rtcAttachGeometryByID(scene_, geom, static_cast<unsigned>(m));
    rtcReleaseGeometry(geom);
    check(device_, ("adding mesh '" + mesh.name + "' to the Embree scene").c_str());
  }
  rtcCommitScene(scene_);
  check(device_, "building the Embree BVH");
}

EmbreeScene::~EmbreeScene() {
  if (scene_) rtcReleaseScene(scene_);
  if (device_) rtcReleaseDevice(device_);
}

bool EmbreeScene::intersect(const glm::vec3& o, const glm::vec3& d, float tnear, float tfar, RayHit* hit, bool toward_light) const {
  RTCIntersectContext context;
  rtcInitIntersectContext(&context);
  RTCRayHit rh;
  rh.ray.org_x = o.x, rh.ray.org_y = o.y, rh.ray.org_z = o.z;
  rh.ray.dir_x = d.x, rh.ray.dir_y = d.y, rh.ray.dir_z = d.z;
  rh.ray.tnear = tnear;
  rh.ray.tfar = tfar;
  rh.ray.time = 0.0f;
  rh.ray.mask = 0xFFFFFFFFu;
  rh.ray.id = toward_light ? kTowardLight : 0u;
  rh.ray.flags = 0;
  rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
  rh.hit.instID[0] = RTC_INVALID_GEOMETRY_ID;
  rtcIntersect1(scene_, &context, &rh);
  if (rh.hit.geomID == RTC_INVALID_GEOMETRY_ID) return false;
  hit->t = rh.ray.tfar;
  hit->mesh = rh.hit.geomID;
  hit->triangle = rh.hit.primID;
  hit->u = rh.hit.u;
  hit->v = rh.hit.v;
  return true;
}

void EmbreeScene::intersect_packet(const bool* valid, const glm::vec3& o, const glm::vec3* dirs, float tnear,
                                   float tfar, RayHit* hit, bool* found) const {
  glm::vec3 origins[kPacket];
  float tfars[kPacket];
  for (int i = 0; i < kPacket; ++i) origins[i] = o, tfars[i] = tfar;
  intersect_packet(valid, origins, dirs, tnear, tfars, hit, found);
}

void EmbreeScene::intersect_packet(const bool* valid, const glm::vec3* o, const glm::vec3* dirs, float tnear,
                                   const float* tfar, RayHit* hit, bool* found, bool toward_light) const {
  alignas(64) int lanes[kPacket];
  alignas(64) RTCRayHit16 rh;
  for (int i = 0; i < kPacket; ++i) {
    lanes[i] = valid[i] ? -1 : 0;
    rh.ray.org_x[i] = o[i].x, rh.ray.org_y[i] = o[i].y, rh.ray.org_z[i] = o[i].z;
    rh.ray.dir_x[i] = dirs[i].x, rh.ray.dir_y[i] = dirs[i].y, rh.ray.dir_z[i] = dirs[i].z;
    rh.ray.tnear[i] = tnear;
    rh.ray.tfar[i] = tfar[i];
    rh.ray.time[i] = 0.0f;
    rh.ray.mask[i] = 0xFFFFFFFFu;
    rh.ray.id[i] = static_cast<unsigned>(i) | (toward_light ? kTowardLight : 0u);
    rh.ray.flags[i] = 0;
    rh.hit.geomID[i] = RTC_INVALID_GEOMETRY_ID;
    rh.hit.instID[0][i] = RTC_INVALID_GEOMETRY_ID;
  }
  RTCIntersectContext context;
  rtcInitIntersectContext(&context);
  context.flags = RTC_INTERSECT_CONTEXT_FLAG_COHERENT;
  rtcIntersect16(lanes, scene_, &context, &rh);
  for (int i = 0; i < kPacket; ++i) {
    found[i] = valid[i] && rh.hit.geomID[i] != RTC_INVALID_GEOMETRY_ID;
    if (!found[i]) continue;
    hit[i].t = rh.ray.tfar[i];
    hit[i].mesh = rh.hit.geomID[i];
    hit[i].triangle = rh.hit.primID[i];
    hit[i].u = rh.hit.u[i];
    hit[i].v = rh.hit.v[i];
  }
}

void EmbreeScene::occluded_packet(const bool* valid, const glm::vec3* o, const glm::vec3* dirs, float tnear,
                                  const float* tfar, bool* blocked) const {
  alignas(64) int lanes[kPacket];
  alignas(64) RTCRay16 ray;
  for (int i = 0; i < kPacket; ++i) {
    lanes[i] = valid[i] ? -1 : 0;
    ray.org_x[i] = o[i].x, ray.org_y[i] = o[i].y, ray.org_z[i] = o[i].z;
    ray.dir_x[i] = dirs[i].x, ray.dir_y[i] = dirs[i].y, ray.dir_z[i] = dirs[i].z;
    ray.tnear[i] = tnear;
    ray.tfar[i] = tfar[i];
    ray.time[i] = 0.0f;
    ray.mask[i] = 0xFFFFFFFFu;
    ray.id[i] = static_cast<unsigned>(i) | kTowardLight;
    ray.flags[i] = 0;
  }
  RTCIntersectContext context;
  rtcInitIntersectContext(&context);
  context.flags = RTC_INTERSECT_CONTEXT_FLAG_COHERENT;
  rtcOccluded16(lanes, scene_, &context, &ray);
  for (int i = 0; i < kPacket; ++i) blocked[i] = valid[i] && ray.tfar[i] < 0.0f;
}

bool EmbreeScene::occluded(const glm::vec3& o, const glm::vec3& d, float tnear, float tfar) const {
  RTCIntersectContext context;
  rtcInitIntersectContext(&context);
  RTCRay ray;
  ray.org_x = o.x, ray.org_y = o.y, ray.org_z = o.z;
  ray.dir_x = d.x, ray.dir_y = d.y, ray.dir_z = d.z;
  ray.tnear = tnear;
  ray.tfar = tfar;
  ray.time = 0.0f;
  ray.mask = 0xFFFFFFFFu;
  ray.id = kTowardLight;
  ray.flags = 0;
  rtcOccluded1(scene_, &context, &ray);
  return ray.tfar < 0.0f;  // Embree sets tfar to -inf when something was hit
}

glm::vec3 offset_ray_origin(const glm::vec3& p, const glm::vec3& n_in, const glm::vec3& dir) {
  constexpr float kOrigin = 1.0f / 32.0f, kFloatScale = 1.0f / 65536.0f;
  const glm::vec3 n = glm::dot(n_in, dir) < 0.0f ? -n_in : n_in;
  glm::vec3 out;
  for (int c = 0; c < 3; ++c) {
    const auto of = static_cast<int32_t>(kOffsetUlps * n[c]);
    const auto bits = std::bit_cast<int32_t>(p[c]);
    const float moved = std::bit_cast<float>(bits + (p[c] < 0.0f ? -of : of));
    out[c] = std::fabs(p[c]) < kOrigin ? p[c] + kFloatScale * n[c] : moved;
  }
  return out;
}

}  // namespace spadgen::render
