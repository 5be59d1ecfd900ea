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

// Orthonormal basis around a unit normal (Duff et al. 2017), in float (glm::vec3) or double (glm::dvec3).
template <class V>
inline void make_basis(const V& n, V* t, V* b) {
  using T = typename V::value_type;
  const T sign = n.z >= T(0) ? T(1) : T(-1);
  const T a = T(-1) / (sign + n.z);
  const T c = n.x * n.y * a;
  *t = V(T(1) + sign * n.x * n.x * a, sign * c, -sign * n.x);
  *b = V(c, sign + n.y * n.y * a, -n.y);
}

}  // namespace spadgen::render
