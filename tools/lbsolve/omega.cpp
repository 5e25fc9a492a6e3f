// omega.cpp: the collision matrix Omega (eq. 2.15-2.17) with the normalised Henyey-Greenstein
// phase (eq. 4.1-4.2). See collide.h.
#include <cassert>
#include <cmath>
#include <cstring>

#include "collide.h"

namespace canopy::lb {
namespace {
// n_i . n_j for directions i, j >= 1 (|c|^2 = number of non-zero components).
double cosAngle(int i, int j) {
  return lattice::dot(i, j) / std::sqrt(double(lattice::dot(i, i) * lattice::dot(j, j)));
}
// Row multiplicity in the normalisation of eq. 4.1: 2 for axial rows, 1 for diagonal rows.
double rowMultiplicity(int i) { return lattice::isAxial(i) ? 2.0 : 1.0; }
// p_ij / (1 - g^2): the Henyey-Greenstein kernel without the factor that cancels.
double hgKernel(double g, double mu) { return 1.0 / std::pow(1.0 + g * g - 2.0 * g * mu, 1.5); }
}  // namespace

double normalisedPhase(double g, int i, int j) {
  assert(i >= 1 && i < kQ && j >= 1 && j < kQ && g >= -1.0 && g <= 1.0);
  if (g == 1.0 || g == -1.0) {
    const int target = g > 0 ? j : lattice::opposite(j);
    return i == target ? 24.0 / rowMultiplicity(i) : 0.0;
  }
  // The normalisation of column j depends on j's class only (axial or diagonal); it is summed for
  // that class's first column, so that the entries of a class in a row are bitwise equal
  // (omegaIsClassStructured) rather than equal up to the order of this sum's terms.
  const int jr = lattice::isAxial(j) ? 1 : 7;
  double norm = 0;
  for (int k = 1; k < kQ; ++k) norm += rowMultiplicity(k) * hgKernel(g, cosAngle(k, jr));
  return hgKernel(g, cosAngle(i, j)) / (norm / 24.0);
}

void buildOmega(double sigmaA, double sigmaS, double g, float col[kQ][kQ]) {
  const double sigmaT = sigmaA + sigmaS;
  // Row 0 (eq. 2.15): f_0 loses everything it holds and gains sigma_a of every direction.
  col[0][0] = -1.0f;
  for (int j = 1; j < kQ; ++j) col[j][0] = float(sigmaA);
  for (int i = 1; i < kQ; ++i) {
    const double w = lattice::isAxial(i) ? 1.0 / 12.0 : 1.0 / 24.0;  // eq. 2.16 / 2.17
    col[0][i] = float(w);  // re-emission of f_0 (only ever non-zero at wood nodes)
    for (int j = 1; j < kQ; ++j) {
      double v = sigmaS * w * normalisedPhase(g, i, j);
      if (i == j) v -= sigmaT;
      col[j][i] = float(v);
    }
  }
}

bool omegaIsClassStructured(const float col[kQ][kQ]) {
  auto same = [](float a, float b) { return std::memcmp(&a, &b, sizeof a) == 0; };
  for (int i = 0; i < kQ; ++i)
    for (int j = 1; j < kQ; ++j) {
      // the class's first member: row 0 has one class (every j >= 1); row i > 0 the smallest
      // j' >= 1 of the same kind (axial or diagonal) with the same c_i . c_j'
      int rep = 1;
      if (i > 0)
        while (lattice::isAxial(rep) != lattice::isAxial(j) || lattice::dot(i, rep) != lattice::dot(i, j)) ++rep;
      if (!same(col[j][i], col[rep][i])) return false;
    }
  return true;
}

OmegaSet makeOmegaSet(double sigmaA, double sigmaS, double g, double gWood, double sigma) {
  OmegaSet s;
  buildOmega(sigmaA, sigmaS, g, s.col[0]);
  buildOmega(sigmaA, sigmaS, gWood, s.col[1]);
  s.beerLambert = sigma > 0 ? 1 : 0;
  s.sigmaT = float(sigmaA + sigmaS);
  s.tau[0] = float(sigma > 0 ? sigma : 0.0);
  s.tau[1] = float(sigma > 0 ? sigma * std::sqrt(2.0) : 0.0);
  return s;
}

}  // namespace canopy::lb
