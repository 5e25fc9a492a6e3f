// affine.h: 3x4 affine matrices in double precision (row-major; the last row 0 0 0 1 implied), as the
// .canopy file stores its transforms: composition, determinant and inverse. Used where the player's
// scene is set up (scene.cpp) and by code that must place instances exactly as it does
// (tests/reference).
#pragma once
#include <array>
#include <cmath>
#include <string>

#include "canopy/errors.h"

namespace canopy::play {

using M34 = std::array<double, 12>;

inline M34 compose(const M34& a, const M34& b) {  // a * b (as 4x4 with last row 0 0 0 1)
  M34 r{};
  for (int i = 0; i < 3; ++i) {
    for (int j = 0; j < 4; ++j) {
      double v = j == 3 ? a[size_t(i * 4 + 3)] : 0.0;
      for (int k = 0; k < 3; ++k) v += a[size_t(i * 4 + k)] * b[size_t(k * 4 + j)];
      r[size_t(i * 4 + j)] = v;
    }
  }
  return r;
}

inline double det3(const M34& m) {
  return m[0] * (m[5] * m[10] - m[6] * m[9]) - m[1] * (m[4] * m[10] - m[6] * m[8]) + m[2] * (m[4] * m[9] - m[5] * m[8]);
}

// The inverse; throws InvalidInput "<what>: singular transform" for a singular or non-finite one.
inline M34 invert(const M34& m, const std::string& what) {
  const double det = det3(m);
  if (!std::isfinite(det) || std::fabs(det) < 1e-18) throw invalidInput(what + ": singular transform");
  const double id = 1.0 / det;
  M34 r{};
  r[0] = (m[5] * m[10] - m[6] * m[9]) * id;
  r[1] = (m[2] * m[9] - m[1] * m[10]) * id;
  r[2] = (m[1] * m[6] - m[2] * m[5]) * id;
  r[4] = (m[6] * m[8] - m[4] * m[10]) * id;
  r[5] = (m[0] * m[10] - m[2] * m[8]) * id;
  r[6] = (m[2] * m[4] - m[0] * m[6]) * id;
  r[8] = (m[4] * m[9] - m[5] * m[8]) * id;
  r[9] = (m[1] * m[8] - m[0] * m[9]) * id;
  r[10] = (m[0] * m[5] - m[1] * m[4]) * id;
  for (int i = 0; i < 3; ++i)
    r[size_t(i * 4 + 3)] = -(r[size_t(i * 4)] * m[3] + r[size_t(i * 4 + 1)] * m[7] + r[size_t(i * 4 + 2)] * m[11]);
  return r;
}

}  // namespace canopy::play
