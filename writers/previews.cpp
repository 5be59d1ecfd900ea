#include "writers/previews.h"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdio>
#include <limits>

#include "core/error.h"
#include "writers/writers.h"

namespace spadgen::writers {
namespace {

using Colour = std::array<uint8_t, 3>;

uint8_t to_byte(double v) { return static_cast<uint8_t>(std::lround(std::clamp(v, 0.0, 1.0) * 255.0)); }

// 5x7 glyphs, one string of 35 cells per character ('#' lit), rows top to bottom.
struct Glyph {
  char c;
  const char* rows;
};
constexpr Glyph kFont[] = {
    {'0', ".###.#...##..###.#.###..##...#.###."}, {'1', "..#...##....#....#....#....#...###."},
    {'2', ".###.#...#....#...#...#...#...#####"}, {'3', "#####...#...#.....#.....##...#.###."},
    {'4', "...#...##..#.#.#..#.#####...#....#."}, {'5', "######....####.....#....##...#.###."},
    {'6', "..##..#...#....####.#...##...#.###."}, {'7', "#####....#...#...#...#....#....#..."},
    {'8', ".###.#...##...#.###.#...##...#.###."}, {'9', ".###.#...##...#.####....#...#..##.."},
    {'.', "..........................##...##.."}, {'-', "...............#####..............."},
    {'+', ".......#....#..#####..#....#......."}, {'(', "...#...#...#....#....#.....#.....#."},
    {')', ".#.....#.....#....#....#...#...#..."}, {'/', ".........#...#...#...#...#........."},
    {'a', "...........###.....#.#####...#.####"}, {'b', "#....#....####.#...##...##...#####."},
    {'c', "...........###.#....#....#...#.###."}, {'d', "....#....#.##.##..###...##...#.####"},
    {'e', "...........###.#...#######.....###."}, {'f', "..##..#..#.#...###...#....#....#..."},
    {'g', "...........#####...#.####....#.###."}, {'h', "#....#....#.##.##..##...##...##...#"},
    {'i', "..#........##....#....#....#...###."}, {'k', "#....#....#..#.#.#..##...#.#..#..#."},
    {'l', ".##....#....#....#....#....#...###."}, {'m', "..........##.#.#.#.##.#.##...##...#"},
    {'n', "..........#.##.##..##...##...##...#"}, {'o', "...........###.#...##...##...#.###."},
    {'p', "..........####.#...#####.#....#...."}, {'r', "..........#.##.##..##....#....#...."},
    {'s', "...........#####.....###.....#####."}, {'t', ".#....#...###...#....#....#..#..##."},
    {'u', "..........#...##...##...##..##.##.#"}, {'x', "..........#...#.#.#...#...#.#.#...#"},
    {'y', "..........#...##...#.####....#.###."},
};

const char* glyph_rows(char c) {
  const char lc = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  for (const auto& g : kFont)
    if (g.c == lc) return g.rows;
  return nullptr;
}

void put(Rgb8Image& im, int x, int y, Colour c) {
  if (x < 0 || y < 0 || x >= im.width || y >= im.height) return;
  uint8_t* p = im.at(x, y);
  p[0] = c[0];
  p[1] = c[1];
  p[2] = c[2];
}

void hline(Rgb8Image& im, int x0, int x1, int y, Colour c) {
  for (int x = x0; x <= x1; ++x) put(im, x, y, c);
}
void vline(Rgb8Image& im, int x, int y0, int y1, Colour c) {
  for (int y = y0; y <= y1; ++y) put(im, x, y, c);
}

std::string format_number(double v, int decimals) {
  char buf[64];
  if (v == 0.0) v = 0.0;  // no "-0"
  std::snprintf(buf, sizeof buf, "%.*f", decimals, v);
  return buf;
}

// Tick spacing of about range / target, rounded to 1, 2 or 5 times a power of ten.
double nice_step(double range, int target) {
  const double raw = range / std::max(1, target);
  const double mag = std::pow(10.0, std::floor(std::log10(raw)));
  const double f = raw / mag;
  return (f < 1.5 ? 1.0 : f < 3.5 ? 2.0 : f < 7.5 ? 5.0 : 10.0) * mag;
}

int decimals_for(double step) { return std::max(0, -int(std::floor(std::log10(step) + 1e-9))); }

std::vector<double> ticks(double lo, double hi, double step) {
  std::vector<double> t;
  const double first = std::ceil(lo / step - 1e-9) * step;
  for (int i = 0;; ++i) {
    const double v = first + i * step;
    if (v > hi + step * 1e-9 || i > 1000) break;
    t.push_back(v);
  }
  return t;
}

// Coverage of a pixel centre by a line of half width hw around segment a-b, with a 1 px linear ramp.
float segment_coverage(double px, double py, double ax, double ay, double bx, double by, double hw) {
  const double dx = bx - ax, dy = by - ay;
  const double len2 = dx * dx + dy * dy;
  double t = len2 > 0 ? ((px - ax) * dx + (py - ay) * dy) / len2 : 0.0;
  t = std::clamp(t, 0.0, 1.0);
  const double ex = ax + t * dx - px, ey = ay + t * dy - py;
  const double d = std::sqrt(ex * ex + ey * ey);
  return static_cast<float>(std::clamp(hw + 0.5 - d, 0.0, 1.0));
}

}  // namespace

Rgb8Image::Rgb8Image(int w, int h, std::array<uint8_t, 3> fill) : width(w), height(h) {
  if (w < 0 || h < 0) throw Error("negative image size");
  pixels.resize(size_t(w) * size_t(h) * 3);
  for (size_t i = 0; i < pixels.size(); i += 3) {
    pixels[i] = fill[0];
    pixels[i + 1] = fill[1];
    pixels[i + 2] = fill[2];
  }
}

void write_png(const std::string& path, const Rgb8Image& image) {
  write_png(path, image.width, image.height, 3, image.pixels);
}

int text_width(const std::string& text) { return text.empty() ? 0 : int(text.size()) * 6 - 1; }

void draw_text(Rgb8Image& image, int x, int y, const std::string& text, std::array<uint8_t, 3> colour) {
  for (size_t i = 0; i < text.size(); ++i) {
    const char* rows = glyph_rows(text[i]);
    if (!rows) continue;
    const int gx = x + int(i) * 6;
    for (int r = 0; r < 7; ++r)
      for (int c = 0; c < 5; ++c)
        if (rows[r * 5 + c] == '#') put(image, gx + c, y + r, colour);
  }
}

std::array<uint8_t, 3> viridis(double t) {
  // Polynomial fit of matplotlib's viridis by Matt Zucker (shadertoy WlfXRN, CC0), evaluated by Horner.
  static constexpr double c[7][3] = {
      {0.2777273272234177, 0.005407344544966578, 0.3340998053353061},
      {0.1050930431085774, 1.404613529898575, 1.384590162594685},
      {-0.3308618287255563, 0.214847559468213, 0.09509516302823659},
      {-4.634230498983486, -5.799100973351585, -19.33244095627987},
      {6.228269936347081, 14.17993336680509, 56.69055260068105},
      {4.776384997670288, -13.74514537774601, -65.35303263337234},
      {-5.435455855934631, 4.645852612178535, 26.3124352495832},
  };
  if (!(t >= 0.0)) t = 0.0;  // also NaN
  t = std::min(t, 1.0);
  std::array<uint8_t, 3> out{};
  for (int ch = 0; ch < 3; ++ch) {
    double v = c[6][ch];
    for (int k = 5; k >= 0; --k) v = v * t + c[k][ch];
    out[size_t(ch)] = to_byte(v);
  }
  return out;
}

Rgb8Image depth_preview(const float* range, int width, int height, float near_m, float far_m, bool legend) {
  if (width < 0 || height < 0) throw Error("depth_preview: negative image size");
  const size_t n = size_t(width) * size_t(height);
  auto is_hit = [](float r) { return std::isfinite(r) && r > 0.0f; };
  double lo = near_m, hi = far_m;
  if (!(hi > lo)) {
    lo = std::numeric_limits<double>::infinity();
    hi = -lo;
    for (size_t i = 0; i < n; ++i)
      if (is_hit(range[i])) {
        lo = std::min(lo, double(range[i]));
        hi = std::max(hi, double(range[i]));
      }
    if (!(hi >= lo)) lo = 0.0, hi = 1.0;  // nothing was hit
    if (hi == lo) hi = lo + 1.0;
  }
  const bool with_legend = legend && width >= 48;
  const int x0 = 3, x1 = width - 4;
  const int decimals = decimals_for(nice_step(hi - lo, 4)) + 1;
  const std::string near_text = format_number(lo, decimals) + " m", far_text = format_number(hi, decimals) + " m",
                    mid_text = format_number((lo + hi) / 2, decimals) + " m";
  // Where the near and far labels do not fit side by side (a narrow crop), the far one goes a row lower.
  const bool two_rows = text_width(near_text) + 4 + text_width(far_text) > x1 + 1 - x0;
  Rgb8Image im(width, height + (with_legend ? kDepthLegendHeight + (two_rows ? kDepthLegendRow : 0) : 0));
  // Near is bright so that the eye reads it as close.
  auto colour_of = [&](double r) { return viridis(1.0 - (r - lo) / (hi - lo)); };
  for (int y = 0; y < height; ++y)
    for (int x = 0; x < width; ++x) {
      const float r = range[size_t(y) * size_t(width) + size_t(x)];
      if (is_hit(r)) put(im, x, y, colour_of(r));
    }
  if (with_legend) {
    const Colour white{255, 255, 255};
    const int bar_top = height + 3, bar_bottom = height + 10;
    for (int x = x0; x <= x1; ++x) {
      const double r = lo + (hi - lo) * (x - x0) / double(x1 - x0);
      vline(im, x, bar_top, bar_bottom, colour_of(r));
    }
    const int tick_y = bar_bottom + 1, label_y = bar_bottom + 5;
    const int xm = (x0 + x1) / 2;
    vline(im, x0, tick_y, tick_y + 2, white);
    vline(im, x1, tick_y, tick_y + 2, white);
    draw_text(im, x0, label_y, near_text, white);
    draw_text(im, x1 + 1 - text_width(far_text), label_y + (two_rows ? kDepthLegendRow : 0), far_text, white);
    // The middle label only where it clears both ends.
    const int mx = xm - text_width(mid_text) / 2;
    if (!two_rows && mx > x0 + text_width(near_text) + 4 && mx + text_width(mid_text) + 4 < x1 + 1 - text_width(far_text)) {
      vline(im, xm, tick_y, tick_y + 2, white);
      draw_text(im, mx, label_y, mid_text, white);
    }
  }
  return im;
}

Rgb8Image gray_preview(const float* values, int width, int height, float gamma, float white_percentile) {
  if (width < 0 || height < 0) throw Error("gray_preview: negative image size");
  if (!(gamma > 0.0f)) throw Error("gray_preview: gamma must be positive");
  const size_t n = size_t(width) * size_t(height);
  std::vector<float> finite;
  finite.reserve(n);
  for (size_t i = 0; i < n; ++i)
    if (std::isfinite(values[i])) finite.push_back(values[i]);
  double white = 0.0;
  if (!finite.empty()) {
    const double p = std::clamp(double(white_percentile), 0.0, 100.0) / 100.0;
    const auto k = static_cast<size_t>(std::floor(p * double(finite.size() - 1)));
    std::nth_element(finite.begin(), finite.begin() + std::ptrdiff_t(k), finite.end());
    white = finite[k];
    // A mostly dark image whose percentile is 0 still shows its few bright pixels.
    if (!(white > 0.0)) white = *std::max_element(finite.begin(), finite.end());
  }
  Rgb8Image im(width, height);
  if (!(white > 0.0)) return im;
  const double inv_gamma = 1.0 / double(gamma);
  for (size_t i = 0; i < n; ++i) {
    const float v = values[i];
    if (!std::isfinite(v) || v <= 0.0f) continue;
    const uint8_t g = to_byte(std::pow(std::min(1.0, double(v) / white), inv_gamma));
    im.pixels[3 * i] = im.pixels[3 * i + 1] = im.pixels[3 * i + 2] = g;
  }
  return im;
}

std::array<uint8_t, 3> plot_colour(size_t i) {
  // Distinct on white and for the common colour-vision deficiencies (Okabe-Ito order, black last).
  static constexpr Colour kPalette[8] = {{0, 114, 178},  {213, 94, 0},  {0, 158, 115}, {204, 121, 167},
                                         {230, 159, 0}, {86, 180, 233}, {180, 160, 0}, {0, 0, 0}};
  return kPalette[i % 8];
}

PlotLayout profile_plot_layout(const std::vector<std::vector<float>>& curves, const std::vector<double>& x,
                               int width, int height, bool x_label, bool y_label) {
  for (size_t i = 0; i < curves.size(); ++i)
    if (curves[i].size() != x.size())
      throw Error("profile_plot: curve " + std::to_string(i) + " has " + std::to_string(curves[i].size()) +
                  " values for " + std::to_string(x.size()) + " x positions");
  PlotLayout L;
  double xlo = std::numeric_limits<double>::infinity(), xhi = -xlo;
  for (double v : x)
    if (std::isfinite(v)) xlo = std::min(xlo, v), xhi = std::max(xhi, v);
  if (!(xhi >= xlo)) xlo = 0, xhi = 1;
  if (xhi == xlo) xlo -= 0.5, xhi += 0.5;
  double ylo = 0.0, yhi = -std::numeric_limits<double>::infinity();
  for (const auto& c : curves)
    for (float v : c)
      if (std::isfinite(v)) ylo = std::min(ylo, double(v)), yhi = std::max(yhi, double(v));
  if (!(yhi > ylo)) yhi = ylo + 1.0;

  const double ystep = nice_step(yhi - ylo, 5);
  L.y_min = std::floor(ylo / ystep + 1e-9) * ystep;
  L.y_max = std::ceil(yhi / ystep - 1e-9) * ystep;
  L.y_ticks = ticks(L.y_min, L.y_max, ystep);
  L.tick_decimals_y = decimals_for(ystep);
  // x spans exactly the data (gate positions are the natural ends); ticks fall inside.
  const double xstep = nice_step(xhi - xlo, std::max(2, width / 80));
  L.x_min = xlo;
  L.x_max = xhi;
  L.x_ticks = ticks(xlo, xhi, xstep);
  L.tick_decimals_x = decimals_for(xstep);

  int label_chars = 1;
  for (double t : L.y_ticks) label_chars = std::max(label_chars, int(format_number(t, L.tick_decimals_y).size()));
  L.left = 6 * label_chars + 6;
  L.top = y_label ? 14 : 6;
  L.right = width - 1 - std::max(8, text_width(format_number(L.x_max, L.tick_decimals_x)) / 2 + 2);
  L.bottom = height - 1 - (x_label ? 24 : 13);
  if (L.right - L.left < 8 || L.bottom - L.top < 8)
    throw Error("profile_plot: " + std::to_string(width) + "x" + std::to_string(height) + " is too small for a plot");
  return L;
}

Rgb8Image profile_plot(const std::vector<std::vector<float>>& curves, const std::vector<double>& x, int width,
                       int height, const std::string& x_label, const std::string& y_label) {
  const PlotLayout L = profile_plot_layout(curves, x, width, height, !x_label.empty(), !y_label.empty());
  const Colour white{255, 255, 255}, black{0, 0, 0}, grid{228, 228, 228}, text{40, 40, 40};
  Rgb8Image im(width, height, white);

  for (double t : L.y_ticks) {
    const int py = int(std::lround(L.py(t)));
    hline(im, L.left + 1, L.right, py, grid);
    hline(im, L.left - 3, L.left - 1, py, black);
    const std::string s = format_number(t, L.tick_decimals_y);
    draw_text(im, L.left - 5 - text_width(s), py - 3, s, text);
  }
  for (double t : L.x_ticks) {
    const int px = int(std::lround(L.px(t)));
    vline(im, px, L.top, L.bottom - 1, grid);
    vline(im, px, L.bottom + 1, L.bottom + 3, black);
    const std::string s = format_number(t, L.tick_decimals_x);
    draw_text(im, px - text_width(s) / 2, L.bottom + 5, s, text);
  }
  if (!x_label.empty()) draw_text(im, (L.left + L.right - text_width(x_label)) / 2, L.bottom + 15, x_label, text);
  if (!y_label.empty()) draw_text(im, std::max(0, L.left - 3 * 6), 3, y_label, text);

  // Per curve, the coverage of all its segments is merged with max before blending, so joints and
  // steep zigzags do not get darker than the line itself.
  const double hw = 0.75;
  std::vector<float> cover(size_t(width) * size_t(height));
  for (size_t ci = 0; ci < curves.size(); ++ci) {
    std::fill(cover.begin(), cover.end(), 0.0f);
    int bx0 = width, by0 = height, bx1 = -1, by1 = -1;
    auto stamp = [&](double ax, double ay, double bx, double by) {
      const int x0 = std::max(L.left + 1, int(std::floor(std::min(ax, bx) - hw - 1)));
      const int x1 = std::min(L.right, int(std::ceil(std::max(ax, bx) + hw + 1)));
      const int y0 = std::max(L.top, int(std::floor(std::min(ay, by) - hw - 1)));
      const int y1 = std::min(L.bottom - 1, int(std::ceil(std::max(ay, by) + hw + 1)));
      for (int y = y0; y <= y1; ++y)
        for (int xx = x0; xx <= x1; ++xx) {
          float& c = cover[size_t(y) * size_t(width) + size_t(xx)];
          c = std::max(c, segment_coverage(xx, y, ax, ay, bx, by, hw));
        }
      bx0 = std::min(bx0, x0), by0 = std::min(by0, y0), bx1 = std::max(bx1, x1), by1 = std::max(by1, y1);
    };
    const auto& c = curves[ci];
    bool have_prev = false;
    double prev_x = 0, prev_y = 0;
    for (size_t j = 0; j < x.size(); ++j) {
      if (!std::isfinite(c[j]) || !std::isfinite(x[j])) {
        have_prev = false;
        continue;
      }
      const double px = L.px(x[j]), py = L.py(c[j]);
      const bool isolated = !have_prev && (j + 1 >= x.size() || !std::isfinite(c[j + 1]) || !std::isfinite(x[j + 1]));
      if (have_prev) stamp(prev_x, prev_y, px, py);
      else if (isolated) stamp(px, py, px, py);  // a lone point still shows as a dot
      prev_x = px, prev_y = py, have_prev = true;
    }
    const Colour col = plot_colour(ci);
    for (int y = by0; y <= by1; ++y)
      for (int xx = bx0; xx <= bx1; ++xx) {
        const float a = cover[size_t(y) * size_t(width) + size_t(xx)];
        if (a <= 0.0f) continue;
        uint8_t* p = im.at(xx, y);
        for (int k = 0; k < 3; ++k)
          p[k] = static_cast<uint8_t>(std::lround(p[k] * (1.0f - a) + col[size_t(k)] * a));
      }
  }
  // Axes last, so curves running along zero do not hide them.
  vline(im, L.left, L.top, L.bottom, black);
  hline(im, L.left, L.right, L.bottom, black);
  return im;
}

}  // namespace spadgen::writers
