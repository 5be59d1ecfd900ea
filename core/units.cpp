#include "core/units.h"

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>

namespace spadgen {

double times_ten_to(double v, int k) {
  if (k == 0 || !std::isfinite(v) || v == 0.0) return v;
  char text[48];
  for (int digits = 15; digits <= 17; ++digits) {
    std::snprintf(text, sizeof text, "%.*e", digits - 1, v);
    if (std::strtod(text, nullptr) == v) break;
  }
  char* e = std::strchr(text, 'e');
  const long exponent = std::strtol(e + 1, nullptr, 10) + k;
  std::snprintf(e, sizeof text - size_t(e - text), "e%ld", exponent);
  return std::strtod(text, nullptr);
}

}  // namespace spadgen
