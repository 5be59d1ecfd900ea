#include "core/units.h"

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>
#include <utility>
#include <algorithm>

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

namespace {
// The unit bytes_text gives `bytes` in: its size, name and digits after the point.
struct SizeUnit {
  double scale;
  const char* name;
  int digits;
};
SizeUnit size_unit(double bytes) {
  if (bytes >= 1e12) return {1e12, "TB", 1};  // (22202.3 GB read as 22.2 TB)
  if (bytes >= 1e9) return {1e9, "GB", 1};
  // (below 10 of the unit, one digit more: 1.44 MB read as "1 MB", and "at least 2 MB ... at most 2 MB")
  if (bytes >= 1e6) return {1e6, "MB", bytes < 9.95e6 ? 1 : 0};
  return {1e3, "kB", bytes < 9.95e3 ? 1 : 0};
}
std::string in_unit(double bytes, const SizeUnit& u, int digits) {
  char buf[48];
  std::snprintf(buf, sizeof buf, "%.*f %s", digits, bytes / u.scale, u.name);
  return buf;
}
}  // namespace

std::string bytes_text(int64_t bytes) {
  const SizeUnit u = size_unit(double(bytes));
  return in_unit(double(bytes), u, u.digits);
}

std::pair<std::string, std::string> bytes_texts(int64_t a, int64_t b) {
  std::pair<std::string, std::string> t{bytes_text(a), bytes_text(b)};
  if (t.first != t.second || a == b) return t;
  const SizeUnit u = size_unit(double(std::max(a, b)));  // (they read the same: the larger's unit)
  for (int digits = 1; digits <= 3; ++digits)
    if (t = {in_unit(double(a), u, digits), in_unit(double(b), u, digits)}; t.first != t.second) return t;
  return {std::to_string(a) + " bytes", std::to_string(b) + " bytes"};
}

}  // namespace spadgen
