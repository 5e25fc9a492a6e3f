// image_error.h: the benchmarks' image difference of two frames (premultiplied RGBA floats of the
// same size): RMS over every float, and that RMS relative to the mean RGB of the reference's
// covered pixels (alpha > 0.5). bench-play, bench-stereo and bench-image-diff report it.
#pragma once
#include <algorithm>
#include <cmath>
#include <cstddef>
#include <vector>

namespace canopy::play::bench {

struct ImageError {
  double rms = 0.0, relative = 0.0;
};

inline ImageError imageError(const std::vector<float>& got, const std::vector<float>& ref) {
  double se = 0.0, mean = 0.0;
  size_t covered = 0;
  for (size_t i = 0; i < got.size() && i < ref.size(); ++i) se += double(got[i] - ref[i]) * (got[i] - ref[i]);
  for (size_t p = 0; p + 3 < ref.size(); p += 4)
    if (ref[p + 3] > 0.5f) mean += double(ref[p]) + ref[p + 1] + ref[p + 2], covered += 3;
  ImageError e;
  e.rms = std::sqrt(se / double(std::max<size_t>(got.size(), 1)));
  e.relative = covered && mean > 0.0 ? e.rms / (mean / double(covered)) : 0.0;
  return e;
}

}  // namespace canopy::play::bench
