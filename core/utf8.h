// Well-formed UTF-8 (Unicode Table 3-7: no overlong forms, no surrogates, nothing past U+10FFFF): checks for
// JSON, which holds UTF-8 text only, and for messages, which must stay text whatever bytes a damaged file
// gives a library to echo.
#pragma once
#include <cstddef>
#include <cstdio>
#include <string>

namespace spadgen {

// The length (1 to 4) of the well-formed UTF-8 sequence starting at text[i], or 0 when none does.
inline size_t utf8_sequence_at(const std::string& text, size_t i) {
  const auto* b = reinterpret_cast<const unsigned char*>(text.data());
  const size_t n = text.size();
  const unsigned c = b[i];
  size_t len;
  unsigned lo = 0x80, hi = 0xBF;  // the range of the second byte
  if (c < 0x80) return 1;
  if (c >= 0xC2 && c <= 0xDF) len = 2;
  else if (c >= 0xE0 && c <= 0xEF) len = 3, lo = c == 0xE0 ? 0xA0 : 0x80, hi = c == 0xED ? 0x9F : 0xBF;
  else if (c >= 0xF0 && c <= 0xF4) len = 4, lo = c == 0xF0 ? 0x90 : 0x80, hi = c == 0xF4 ? 0x8F : 0xBF;
  else return 0;
  if (len > n - i) return 0;
  for (size_t k = 1; k < len; ++k)
    if (b[i + k] < (k == 1 ? lo : 0x80) || b[i + k] > (k == 1 ? hi : 0xBF)) return 0;
  return len;
}

// The offset of the first byte of `text` that is not part of well-formed UTF-8, or std::string::npos. JSON
// holds UTF-8 text only: a --set value or a path that is not would make writing metadata.json fail after the
// whole run.
inline size_t invalid_utf8_at(const std::string& text) {
  for (size_t i = 0; i < text.size();) {
    const size_t len = utf8_sequence_at(text, i);
    if (len == 0) return i;
    i += len;
  }
  return std::string::npos;
}

// `text` with every byte that is not part of well-formed UTF-8 written \xNN (the rest as it is).
inline std::string escape_invalid_utf8(const std::string& text) {
  if (invalid_utf8_at(text) == std::string::npos) return text;
  std::string out;
  for (size_t i = 0; i < text.size();) {
    const size_t len = utf8_sequence_at(text, i);
    if (len > 0) {
      out.append(text, i, len);
      i += len;
    } else {
      char hex[8];
      std::snprintf(hex, sizeof hex, "\\x%02X", static_cast<unsigned char>(text[i]));
      out += hex;
      ++i;
    }
  }
  return out;
}

}  // namespace spadgen
