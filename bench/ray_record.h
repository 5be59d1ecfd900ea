// One ray as the integrator traced it, recorded by bench_render_rays and replayed by bench_render through
// raw rtcIntersect1 / rtcOccluded1.
#pragma once
#include <cstdint>

namespace spadgen::bench {

struct RayRecord {
  float origin[3], dir[3];
  float tnear, tfar;
  uint32_t occlusion;  // 1: rtcOccluded1 (else rtcIntersect1)
  uint32_t id;         // the ray's id: its render::kTowardLight bit decides which side the back-face filter culls
};

}  // namespace spadgen::bench
