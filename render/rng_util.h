// Small sampling helpers shared by the BSDFs and the integrator.
#pragma once
#include <glm/glm.hpp>

#include "core/rng.h"

namespace spadgen::render {

struct Uniform3 {
  float a, b, c;
};

inline float uniform(Rng& rng) { return rng.next_float(); }
inline Uniform3 uniform3(Rng& rng) {
  const float a = rng.next_float(), b = rng.next_float(), c = rng.next_float();
  return {a, b, c};
}

// Orthonormal basis around a unit normal (Duff et al. 2017).
inline void make_basis(const glm::vec3& n, glm::vec3* t, glm::vec3* b) {
  const float sign = n.z >= 0.0f ? 1.0f : -1.0f;
  const float a = -1.0f / (sign + n.z);
  const float c = n.x * n.y * a;
  *t = glm::vec3(1.0f + sign * n.x * n.x * a, sign * c, -sign * n.x);
  *b = glm::vec3(c, sign + n.y * n.y * a, -n.y);
}

}  // namespace spadgen::render
