// plot.h: a small line-plot rasteriser writing PNG (libpng; text with stb_easy_font), for the
// threshold sweep. Axes with tick labels, axis titles, a legend, optional log10 axes.
#pragma once
#include <array>
#include <string>
#include <vector>

namespace canopy::haar {

struct PlotSeries {
  std::string label;                     // legend entry ("" = not in the legend)
  std::vector<double> x, y;              // points, drawn in order; non-positive values skipped on log axes
  std::vector<std::string> pointLabels;  // optional text beside each point
  std::array<unsigned char, 3> color{0, 0, 0};
  float width = 1.5f;
  bool markers = false;
};

struct PlotSpec {
  std::string title, xLabel, yLabel;
  bool logX = false, logY = false;
  int width = 1100, height = 760;
  std::vector<PlotSeries> series;
  std::vector<std::string> notes;  // extra lines under the legend
};

// Throws canopy::Error(Io) naming the path if it cannot be written.
void writePlotPng(const std::string& path, const PlotSpec& spec);

}  // namespace canopy::haar
