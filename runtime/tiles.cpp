// tiles.cpp: see tiles.h.
#include "runtime/tiles.h"

#include <algorithm>
#include <cmath>

namespace canopy::play {
namespace {

// Boundaries b[0] = 0 < b[1] < ... < b[n] = height, snapped to `align` and at least `minRows` apart.
std::vector<Band> bandsFromBoundaries(std::vector<double> b, int height, int align) {
  const int n = int(b.size()) - 1;
  const int minRows = height >= n * align ? align : 1;
  const int step = height >= n * align ? align : 1;
  std::vector<Band> out(static_cast<size_t>(n));
  int prev = 0;
  for (int k = 1; k <= n; ++k) {
    int y = k == n ? height : int(std::lround(b[size_t(k)] / step)) * step;
    y = std::max(y, prev + minRows);                 // room for this band
    y = std::min(y, height - (n - k) * minRows);     // and for the bands after it
    out[size_t(k - 1)] = Band{prev, y};
    prev = y;
  }
  return out;
}

}  // namespace

std::vector<Band> equalBands(int height, int n, int align) {
  n = std::max(1, std::min(n, height));
  std::vector<double> b(size_t(n) + 1);
  for (int k = 0; k <= n; ++k) b[size_t(k)] = double(height) * k / n;
  return bandsFromBoundaries(b, height, align);
}

std::vector<Band> balanceBands(const std::vector<Band>& bands, const std::vector<double>& cost, int height, int align) {
  const size_t n = bands.size();
  double total = 0.0;
  for (size_t k = 0; k < n; ++k) total += std::max(cost[k], 0.0);
  if (n < 2 || !(total > 0.0) || !std::isfinite(total)) return bands;
  // The cumulative cost is piecewise linear over the rows (even within each band); the k-th new
  // boundary is where it reaches k / n of the total.
  std::vector<double> b(n + 1);
  b[0] = 0.0;
  b[n] = double(height);
  size_t band = 0;
  double before = 0.0;  // cost of the bands before `band`
  for (size_t k = 1; k < n; ++k) {
    const double target = total * double(k) / double(n);
    while (band + 1 < n && before + std::max(cost[band], 0.0) < target) before += std::max(cost[band++], 0.0);
    const double c = std::max(cost[band], 0.0);
    const double f = c > 0.0 ? std::min(1.0, (target - before) / c) : 0.0;
    const double y = bands[band].y0 + f * bands[band].rows();
    b[k] = 0.5 * (double(bands[k].y0) + y);  // half way from the old boundary
  }
  return bandsFromBoundaries(b, height, align);
}

}  // namespace canopy::play
