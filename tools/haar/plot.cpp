// plot.cpp: see plot.h. A software rasteriser: anti-aliased thick lines (distance-to-segment
// coverage), filled rectangles, stb_easy_font text (axis-aligned quads, scaled, optionally rotated
// 90 degrees for the y-axis title), written as 8-bit RGB PNG with libpng.
#include "plot.h"

#include <png.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <vector>

#include "canopy/atomic_file.h"
#include "canopy/errors.h"

#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wunused-function"
#include "stb_easy_font.h"
#pragma GCC diagnostic pop

namespace canopy::haar {
namespace {

using Color = std::array<unsigned char, 3>;

class Canvas {
 public:
  Canvas(int w, int h) : w_(w), h_(h), px_(size_t(w) * h * 3, 255) {}
  int width() const { return w_; }
  int height() const { return h_; }
  const std::vector<unsigned char>& pixels() const { return px_; }

  void blend(int x, int y, const Color& c, float a) {
    if (x < 0 || y < 0 || x >= w_ || y >= h_ || a <= 0) return;
    a = std::min(a, 1.0f);
    unsigned char* p = &px_[(size_t(y) * w_ + x) * 3];
    for (int i = 0; i < 3; ++i) p[i] = (unsigned char)std::lround(p[i] * (1 - a) + c[size_t(i)] * a);
  }
  void fillRect(int x0, int y0, int x1, int y1, const Color& c) {
    for (int y = std::max(0, y0); y < std::min(h_, y1); ++y)
      for (int x = std::max(0, x0); x < std::min(w_, x1); ++x) blend(x, y, c, 1);
  }
  // Anti-aliased segment of the given width.
  void line(double x0, double y0, double x1, double y1, const Color& c, double width) {
    const double r = width / 2;
    const int xa = int(std::floor(std::min(x0, x1) - r - 1)), xb = int(std::ceil(std::max(x0, x1) + r + 1));
    const int ya = int(std::floor(std::min(y0, y1) - r - 1)), yb = int(std::ceil(std::max(y0, y1) + r + 1));
    const double dx = x1 - x0, dy = y1 - y0, len2 = dx * dx + dy * dy;
    for (int y = ya; y <= yb; ++y)
      for (int x = xa; x <= xb; ++x) {
        const double px = x + 0.5, py = y + 0.5;
        double t = len2 > 0 ? ((px - x0) * dx + (py - y0) * dy) / len2 : 0;
        t = std::clamp(t, 0.0, 1.0);
        const double ex = px - (x0 + t * dx), ey = py - (y0 + t * dy);
        const double d = std::sqrt(ex * ex + ey * ey);
        blend(x, y, c, float(std::clamp(r + 0.5 - d, 0.0, 1.0)));
      }
  }
  void disc(double cx, double cy, double r, const Color& c) {
    for (int y = int(cy - r - 1); y <= int(cy + r + 1); ++y)
      for (int x = int(cx - r - 1); x <= int(cx + r + 1); ++x) {
        const double d = std::hypot(x + 0.5 - cx, y + 0.5 - cy);
        blend(x, y, c, float(std::clamp(r + 0.5 - d, 0.0, 1.0)));
      }
  }
  // Text with its top-left at (x, y); scale = pixels per font unit. rotated: reads bottom to top.
  void text(double x, double y, const std::string& s, const Color& c, int scale, bool rotated = false) {
    std::vector<char> buf(s.begin(), s.end());
    buf.push_back('\0');
    static std::vector<unsigned char> vb(size_t(1) << 18);
    unsigned char col[4] = {c[0], c[1], c[2], 255};
    const int quads = stb_easy_font_print(0, 0, buf.data(), col, vb.data(), int(vb.size()));
    for (int q = 0; q < quads; ++q) {
      const float* v = reinterpret_cast<const float*>(&vb[size_t(q) * 64]);  // 4 vertices x 16 bytes
      const float qx0 = v[0], qy0 = v[1], qx1 = v[8], qy1 = v[9];
      if (!rotated)
        fillRect(int(x + qx0 * scale), int(y + qy0 * scale), int(x + qx1 * scale), int(y + qy1 * scale), c);
      else  // (u, v) -> (x + v, y - u)
        fillRect(int(x + qy0 * scale), int(y - qx1 * scale), int(x + qy1 * scale), int(y - qx0 * scale), c);
    }
  }
  static int textWidth(const std::string& s, int scale) {
    std::vector<char> buf(s.begin(), s.end());
    buf.push_back('\0');
    return stb_easy_font_width(buf.data()) * scale;
  }

 private:
  int w_, h_;
  std::vector<unsigned char> px_;
};

struct Axis {
  bool log;
  double lo, hi;  // in plot units (log10 if log)
  double map(double v) const { return log ? std::log10(v) : v; }
};

// Tick positions (plot units) and labels.
void ticks(const Axis& a, std::vector<double>& major, std::vector<std::string>& labels, std::vector<double>& minor) {
  char buf[32];
  if (a.log) {
    for (int e = int(std::floor(a.lo)); e <= int(std::ceil(a.hi)); ++e) {
      if (e >= a.lo - 1e-9 && e <= a.hi + 1e-9) {
        major.push_back(e);
        if (e >= -2 && e <= 3)
          std::snprintf(buf, sizeof buf, "%g", std::pow(10.0, e));
        else
          std::snprintf(buf, sizeof buf, "1e%d", e);
        labels.push_back(buf);
      }
      for (int m = 2; m <= 9; ++m) {
        const double v = e + std::log10(double(m));
        if (v > a.lo && v < a.hi) minor.push_back(v);
      }
    }
    if (major.size() < 3) {  // about a decade or less: nice linear steps in value space
      major.clear();
      labels.clear();
      minor.clear();
      const double vlo = std::pow(10.0, a.lo), vhi = std::pow(10.0, a.hi);
      const double raw = (vhi - vlo) / 6, mag = std::pow(10.0, std::floor(std::log10(raw)));
      const double step = raw / mag < 2 ? 2 * mag : raw / mag < 5 ? 5 * mag : 10 * mag;
      for (double v = std::ceil(vlo / step) * step; v <= vhi; v += step) {
        if (v <= 0) continue;
        major.push_back(std::log10(v));
        std::snprintf(buf, sizeof buf, "%g", v);
        labels.push_back(buf);
      }
    }
  } else {
    const double span = a.hi - a.lo;
    const double raw = span / 6, mag = std::pow(10.0, std::floor(std::log10(raw)));
    const double step = raw / mag < 2 ? 2 * mag : raw / mag < 5 ? 5 * mag : 10 * mag;
    for (double v = std::ceil(a.lo / step) * step; v <= a.hi + 1e-9 * span; v += step) {
      major.push_back(v);
      std::snprintf(buf, sizeof buf, "%g", std::abs(v) < 1e-12 * span ? 0.0 : v);
      labels.push_back(buf);
    }
  }
}

Axis makeAxis(const std::vector<PlotSeries>& ss, bool isX, bool log) {
  double lo = INFINITY, hi = -INFINITY;
  for (const auto& s : ss)
    for (double v : isX ? s.x : s.y) {
      if (!std::isfinite(v) || (log && v <= 0)) continue;
      const double m = log ? std::log10(v) : v;
      lo = std::min(lo, m);
      hi = std::max(hi, m);
    }
  if (!std::isfinite(lo)) lo = 0, hi = 1;
  if (hi - lo < 1e-9) lo -= 0.5, hi += 0.5;
  const double pad = 0.06 * (hi - lo);
  lo -= pad;
  hi += pad;
  if (!log && lo > 0 && lo < 0.25 * hi) lo = 0;
  return Axis{log, lo, hi};
}

void savePng(const std::string& path, const Canvas& c) {
  AtomicOutput out(path);
  FILE* f = std::fopen(out.tempPath().c_str(), "wb");
  if (!f) throw ioError(path + ": cannot write");
  png_structp png = png_create_write_struct(PNG_LIBPNG_VER_STRING, nullptr, nullptr, nullptr);
  png_infop info = png ? png_create_info_struct(png) : nullptr;
  if (!png || !info || setjmp(png_jmpbuf(png))) {
    png_destroy_write_struct(&png, &info);
    std::fclose(f);
    throw ioError(path + ": PNG write failed");
  }
  png_init_io(png, f);
  png_set_IHDR(png, info, png_uint_32(c.width()), png_uint_32(c.height()), 8, PNG_COLOR_TYPE_RGB,
               PNG_INTERLACE_NONE, PNG_COMPRESSION_TYPE_DEFAULT, PNG_FILTER_TYPE_DEFAULT);
  png_write_info(png, info);
  for (int y = 0; y < c.height(); ++y)
    png_write_row(png, const_cast<png_bytep>(&c.pixels()[size_t(y) * c.width() * 3]));
  png_write_end(png, nullptr);
  png_destroy_write_struct(&png, &info);
  if (std::fclose(f) != 0) throw ioError(path + ": write failed");
  out.commit();
}

const Color kBlack{0, 0, 0}, kGrid{225, 228, 235}, kGridMinor{242, 243, 247}, kDark{60, 60, 60};

// The plot box in pixels, its axes, and the mapping of plot units to pixels.
struct PlotBox {
  int x0, x1, y0, y1;
  Axis ax, ay;
  double X(double u) const { return x0 + (u - ax.lo) / (ax.hi - ax.lo) * (x1 - x0); }
  double Y(double u) const { return y1 - (u - ay.lo) / (ay.hi - ay.lo) * (y1 - y0); }
  bool inside(double px, double py) const { return px >= x0 - 1 && px <= x1 + 1 && py >= y0 - 1 && py <= y1 + 1; }
};

// Grid lines, the frame, ticks and tick labels.
void drawAxes(Canvas& cv, const PlotBox& b) {
  const int x0 = b.x0, x1 = b.x1, y0 = b.y0, y1 = b.y1;
  std::vector<double> mx, my, nx, ny;
  std::vector<std::string> lx, ly;
  ticks(b.ax, mx, lx, nx);
  ticks(b.ay, my, ly, ny);
  for (double u : nx) cv.line(b.X(u), y0, b.X(u), y1, kGridMinor, 1);
  for (double u : ny) cv.line(x0, b.Y(u), x1, b.Y(u), kGridMinor, 1);
  for (double u : mx) cv.line(b.X(u), y0, b.X(u), y1, kGrid, 1);
  for (double u : my) cv.line(x0, b.Y(u), x1, b.Y(u), kGrid, 1);
  // Frame and tick labels.
  cv.line(x0, y1, x1, y1, kBlack, 1.5);
  cv.line(x0, y0, x0, y1, kBlack, 1.5);
  cv.line(x1, y0, x1, y1, kDark, 1);
  cv.line(x0, y0, x1, y0, kDark, 1);
  for (size_t i = 0; i < mx.size(); ++i) {
    cv.line(b.X(mx[i]), y1, b.X(mx[i]), y1 + 7, kBlack, 1.5);
    cv.text(b.X(mx[i]) - Canvas::textWidth(lx[i], 2) / 2.0, y1 + 12, lx[i], kBlack, 2);
  }
  for (double u : nx) cv.line(b.X(u), y1, b.X(u), y1 + 4, kBlack, 1);
  for (size_t i = 0; i < my.size(); ++i) {
    cv.line(x0 - 7, b.Y(my[i]), x0, b.Y(my[i]), kBlack, 1.5);
    cv.text(x0 - 12 - Canvas::textWidth(ly[i], 2), b.Y(my[i]) - 7, ly[i], kBlack, 2);
  }
  for (double u : ny) cv.line(x0 - 4, b.Y(u), x0, b.Y(u), kBlack, 1);
}

// The plot's title and the two axis titles.
void drawTitles(Canvas& cv, const PlotBox& b, const PlotSpec& spec) {
  cv.text(b.x0, 20, spec.title, kBlack, 2);
  const std::string xl = spec.xLabel + (spec.logX ? "  [log scale]" : "");
  cv.text((b.x0 + b.x1) / 2.0 - Canvas::textWidth(xl, 2) / 2.0, b.y1 + 48, xl, kBlack, 2);
  const std::string yl = spec.yLabel + (spec.logY ? "  [log scale]" : "");
  cv.text(22, (b.y0 + b.y1) / 2.0 + Canvas::textWidth(yl, 2) / 2.0, yl, kBlack, 2, /*rotated=*/true);
}

// Every series' lines, markers and point labels (clipped to the plot box by skipping points outside).
void drawSeries(Canvas& cv, const PlotBox& b, const PlotSpec& spec) {
  for (const auto& s : spec.series) {
    std::vector<std::pair<double, double>> pts;
    std::vector<std::string> labs;
    for (size_t i = 0; i < s.x.size() && i < s.y.size(); ++i) {
      if ((spec.logX && s.x[i] <= 0) || (spec.logY && s.y[i] <= 0) || !std::isfinite(s.x[i]) || !std::isfinite(s.y[i]))
        continue;
      pts.emplace_back(b.X(b.ax.map(s.x[i])), b.Y(b.ay.map(s.y[i])));
      labs.push_back(i < s.pointLabels.size() ? s.pointLabels[i] : "");
    }
    for (size_t i = 1; i < pts.size(); ++i)
      if (b.inside(pts[i - 1].first, pts[i - 1].second) && b.inside(pts[i].first, pts[i].second))
        cv.line(pts[i - 1].first, pts[i - 1].second, pts[i].first, pts[i].second, s.color, s.width);
    for (size_t i = 0; i < pts.size(); ++i) {
      if (!b.inside(pts[i].first, pts[i].second)) continue;
      if (s.markers) cv.disc(pts[i].first, pts[i].second, s.width + 2, s.color);
      if (!labs[i].empty()) cv.text(pts[i].first + 10, pts[i].second - 24, labs[i], s.color, 2);
    }
  }
}

// The legend right of the plot box, then the notes under it.
void drawLegend(Canvas& cv, const PlotBox& b, const PlotSpec& spec) {
  int ly0 = b.y0 + 10;
  const int lx0 = b.x1 + 20;
  for (const auto& s : spec.series) {
    if (s.label.empty()) continue;
    cv.line(lx0, ly0 + 6, lx0 + 36, ly0 + 6, s.color, s.width);
    if (s.markers) cv.disc(lx0 + 18, ly0 + 6, s.width + 2, s.color);
    cv.text(lx0 + 44, ly0, s.label, kBlack, 2);
    ly0 += 28;
  }
  ly0 += 10;
  for (const auto& n : spec.notes) {
    // Wrap long notes at ~26 characters per line on word boundaries.
    std::string line, word;
    auto flush = [&] {
      if (!line.empty()) cv.text(lx0, ly0, line, kDark, 1), ly0 += 14;
      line.clear();
    };
    for (size_t i = 0; i <= n.size(); ++i) {
      if (i == n.size() || n[i] == ' ') {
        if (line.size() + word.size() + 1 > 40) flush();
        line += (line.empty() ? "" : " ") + word;
        word.clear();
      } else {
        word += n[i];
      }
    }
    flush();
    ly0 += 6;
  }
}

}  // namespace

void writePlotPng(const std::string& path, const PlotSpec& spec) {
  Canvas cv(spec.width, spec.height);
  const int left = 110, right = 300, top = 60, bottom = 90;
  const int x0 = left, x1 = spec.width - right, y0 = top, y1 = spec.height - bottom;
  const Axis ax = makeAxis(spec.series, true, spec.logX), ay = makeAxis(spec.series, false, spec.logY);
  const PlotBox box{x0, x1, y0, y1, ax, ay};
  drawAxes(cv, box);
  drawTitles(cv, box, spec);
  drawSeries(cv, box, spec);
  drawLegend(cv, box, spec);
  savePng(path, cv);
}

}  // namespace canopy::haar
