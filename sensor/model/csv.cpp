#include "sensor/model/csv.h"

#include <cerrno>
#include <cmath>
#include <cstdlib>
#include <fstream>
#include <sstream>

#include "core/error.h"

namespace spadgen::sensor {
namespace {

// Parses exactly two finite decimal numbers separated by a comma, a semicolon or white space. Only decimal
// digits, signs, points and exponents make a number (strtod read "0x10" as 16, and a NUL byte ended the line).
bool parse_row(const std::string& line, double& a, double& b) {
  std::string s = line;
  for (char& ch : s) {
    if (ch == ',' || ch == ';' || ch == '\t') ch = ' ';
    else if (!(ch == ' ' || ch == '\r' || ch == '+' || ch == '-' || ch == '.' || ch == 'e' || ch == 'E' || (ch >= '0' && ch <= '9')))
      return false;
  }
  const char* p = s.c_str();
  char* end = nullptr;
  errno = 0;
  a = std::strtod(p, &end);
  if (end == p || errno != 0) return false;
  p = end;
  b = std::strtod(p, &end);
  if (end == p || errno != 0) return false;
  for (p = end; *p != '\0'; ++p)
    if (*p != ' ' && *p != '\r') return false;
  return std::isfinite(a) && std::isfinite(b);
}

}  // namespace

Table2 read_table_csv(const std::string& path, const std::string& key) {
  std::ifstream in(path);
  if (!in) throw Error(key + ": cannot read the table file '" + path + "'");
  Table2 t;
  std::string line;
  int line_no = 0;
  bool first_data_row = true;
  while (std::getline(in, line)) {
    ++line_no;
    const auto first = line.find_first_not_of(" \t\r");
    if (first == std::string::npos || line[first] == '#') continue;
    double a = 0, b = 0;
    if (!parse_row(line, a, b)) {
      // A header such as "time_ps,response"; a row that starts with a number is data, however malformed
      // (a 3-column first row was skipped as a header and the table read without it).
      const auto digit = [&](size_t i) { return i < line.size() && line[i] >= '0' && line[i] <= '9'; };
      const char c = line[first];
      const bool sign = c == '+' || c == '-' || c == '.';
      const bool numeric = digit(first) || (sign && (digit(first + 1) || (line[first + 1] == '.' && digit(first + 2))));
      if (first_data_row && !numeric) {
        first_data_row = false;
        continue;
      }
      throw Error(key + ": '" + path + "' line " + std::to_string(line_no) +
                  ": expected two numbers separated by a comma, found '" + line + "'");
    }
    first_data_row = false;
    if (!t.x.empty() && !(a > t.x.back())) {
      std::ostringstream m;
      m << key << ": '" << path << "' line " << line_no << ": the first column must be strictly increasing, found "
        << a << " after " << t.x.back();
      throw Error(m.str());
    }
    t.x.push_back(a);
    t.y.push_back(b);
  }
  if (t.x.size() < 2)
    throw Error(key + ": '" + path + "' must hold at least two rows of numbers, found " + std::to_string(t.x.size()));
  return t;
}

}  // namespace spadgen::sensor
