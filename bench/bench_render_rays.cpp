// Records the rays the integrator traces for bench_render's image (1 sample per pixel, every pixel) and
// writes them to stdout: a uint64 count, then that many bench::RayRecord. bench_render runs this program
// and replays the rays through raw Embree.
//
// The recording sits at Embree's C API, not in render/: this program alone is linked with
// --wrap=rtcIntersect1 (and rtcOccluded1, rtcIntersect16, rtcOccluded16), so the renderer's calls reach
// the __wrap_ functions below, which note each valid ray and call Embree. bench_render itself is linked
// without them, so the integrator it times is the renderer as shipped.
#include <embree3/rtcore.h>
#include <tbb/global_control.h>
#include <unistd.h>

#include <cstdint>
#include <cstdio>
#include <exception>
#include <vector>

#include "ray_record.h"
#include "render/renderer.h"
#include "render_setup.h"

extern "C" {
void __real_rtcIntersect1(RTCScene scene, RTCIntersectContext* context, RTCRayHit* rayhit);
void __real_rtcOccluded1(RTCScene scene, RTCIntersectContext* context, RTCRay* ray);
void __real_rtcIntersect16(const int* valid, RTCScene scene, RTCIntersectContext* context, RTCRayHit16* rayhit);
void __real_rtcOccluded16(const int* valid, RTCScene scene, RTCIntersectContext* context, RTCRay16* ray);
}

namespace {

using spadgen::bench::RayRecord;

// Only the main thread renders while this is set (TBB limited to one thread), so no lock is needed.
std::vector<RayRecord>* g_sink = nullptr;

void note(const RTCRay& r, bool occlusion) {
  g_sink->push_back({{r.org_x, r.org_y, r.org_z}, {r.dir_x, r.dir_y, r.dir_z}, r.tnear, r.tfar, occlusion ? 1u : 0u, r.id});
}

template <class Ray16>
void note16(const int* valid, const Ray16& r, bool occlusion) {
  // A packet's rays are replayed one by one, in lane order.
  for (int i = 0; i < 16; ++i)
    if (valid[i] == -1)
      g_sink->push_back({{r.org_x[i], r.org_y[i], r.org_z[i]},
                         {r.dir_x[i], r.dir_y[i], r.dir_z[i]},
                         r.tnear[i],
                         r.tfar[i],
                         occlusion ? 1u : 0u,
                         r.id[i]});
}

}  // namespace

extern "C" {
void __wrap_rtcIntersect1(RTCScene scene, RTCIntersectContext* context, RTCRayHit* rayhit) {
  if (g_sink) note(rayhit->ray, false);
  __real_rtcIntersect1(scene, context, rayhit);
}
void __wrap_rtcOccluded1(RTCScene scene, RTCIntersectContext* context, RTCRay* ray) {
  if (g_sink) note(*ray, true);
  __real_rtcOccluded1(scene, context, ray);
}
void __wrap_rtcIntersect16(const int* valid, RTCScene scene, RTCIntersectContext* context, RTCRayHit16* rayhit) {
  if (g_sink) note16(valid, rayhit->ray, false);
  __real_rtcIntersect16(valid, scene, context, rayhit);
}
void __wrap_rtcOccluded16(const int* valid, RTCScene scene, RTCIntersectContext* context, RTCRay16* ray) {
  if (g_sink) note16(valid, *ray, true);
  __real_rtcOccluded16(valid, scene, context, ray);
}
}

int main() {
  using namespace spadgen;
  if (isatty(fileno(stdout))) {
    std::fprintf(stderr, "bench_render_rays writes binary rays to stdout; bench_render runs it\n");
    return 2;
  }
  try {
    bench::Setup& s = bench::setup();
    RunConfig c = s.config;
    c.render.samples_per_pixel = 1;
    const render::Renderer r(s.scene, bench::stage(c));
    std::vector<RayRecord> rays;
    rays.reserve(8u << 20);
    {
      tbb::global_control one(tbb::global_control::max_allowed_parallelism, 1);
      g_sink = &rays;
      // The rays do not depend on the time axis, so none is kept while recording.
      bench::render_image(r, c, TimeAxis{}, {0, 0, c.camera.width_px, c.camera.height_px});
      g_sink = nullptr;
    }
    const uint64_t n = rays.size();
    if (std::fwrite(&n, sizeof n, 1, stdout) != 1 || std::fwrite(rays.data(), sizeof(RayRecord), n, stdout) != n ||
        std::fflush(stdout) != 0) {
      std::fprintf(stderr, "bench_render_rays: could not write the rays\n");
      return 1;
    }
  } catch (const std::exception& e) {
    std::fprintf(stderr, "bench_render_rays: %s\n", e.what());
    return 1;
  }
  return 0;
}
