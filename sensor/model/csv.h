// Two-column numeric tables (measured gate profiles, laser pulse shapes, PDP curves) read from CSV.
#pragma once
#include <string>
#include <vector>

namespace spadgen::sensor {

struct Table2 {
  std::vector<double> x, y;
};

// Reads "x, y" rows (comma, semicolon, tab or space separated). Blank lines and lines starting with '#'
// are skipped; a first row that does not parse as two numbers is taken as a header. Throws spadgen::Error
// naming `key` and the file when the file cannot be read, a row is malformed, there are fewer than two
// rows, or x is not strictly increasing.
Table2 read_table_csv(const std::string& path, const std::string& key);

}  // namespace spadgen::sensor
