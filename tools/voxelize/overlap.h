// overlap.h: triangle / axis-aligned unit box overlap in a fine grid, one triangle set up once.
//
// The test is the separating-axis theorem in Schwarz & Seidel's form ("Fast parallel surface and
// solid voxelization on GPUs", 2010): given that the box overlaps the triangle's bounding box, the
// closed unit box [p, p+1]^3 meets the closed triangle iff (1) the triangle's plane separates the
// box's two critical corners (or touches one), and (2) in each of the xy, yz and zx projections the
// box's projected square meets the projected triangle (three edge functions >= 0). These are the
// 13 SAT axes (3 box normals, the triangle normal, 9 edge x axis cross products).
//
// Everything is evaluated in double precision on coordinates local to an integer origin (the
// subtraction of an integer is exact). The signs of the normal's components (= the orientations
// of the three projected triangles) choose the critical corners and the edge-normal directions; a
// wrong sign flips whole tests, so the caller passes them computed exactly (CGAL's orientation
// predicate, exact_overlap.cpp). Each decision value then carries a forward error bound (`tolPlane`
// for the degree-3 plane values, `tolEdge` for the degree-2 edge values); when a value falls inside
// its band the result is "Ambiguous" and the caller decides exactly (CGAL's filtered exact
// triangle/box predicate). Only geometry lying (almost) on fine-cell faces, edges or corners gets
// there.
// The functions are CANOPY_HD: one definition for the TBB path and any CUDA kernel.
#pragma once
#include <cfloat>
#include <cmath>

#include "canopy/hd.h"

namespace canopy::vox {

struct TriBoxSetup {
  double v0[3];
  double n[3];        // (v1 - v0) x (v2 - v0)
  double d1, d2;      // plane test offsets (critical corners)
  double ne[3][3][2]; // [projection xy,yz,zx][edge][2] edge normals
  double de[3][3];    // edge offsets
  double tolPlane, tolEdge;  // error bands of the decision values
};

enum class Overlap { No = 0, Yes = 1, Ambiguous = 2 };

CANOPY_HD inline double maxd(double a, double b) { return a > b ? a : b; }
CANOPY_HD inline double absd(double a) { return a < 0 ? -a : a; }

// Vertices in local fine-grid coordinates; M bounds |coordinate| of the vertices and of any box
// corner the triangle will be tested against (the triangle's local bounding box plus one).
// sign[k] in {-1, 0, 1} is the exact sign of n[k] ((b-a) x (c-a)).
CANOPY_HD inline TriBoxSetup setupTriBox(const double a[3], const double b[3], const double c[3],
                                         double M, const int sign[3]) {
  TriBoxSetup s;
  const double* v[3] = {a, b, c};
  double e[3][3];
  for (int i = 0; i < 3; ++i)
    for (int k = 0; k < 3; ++k) e[i][k] = v[(i + 1) % 3][k] - v[i][k];
  for (int k = 0; k < 3; ++k) s.v0[k] = a[k];
  s.n[0] = e[0][1] * (-e[2][2]) - e[0][2] * (-e[2][1]);
  s.n[1] = e[0][2] * (-e[2][0]) - e[0][0] * (-e[2][2]);
  s.n[2] = e[0][0] * (-e[2][1]) - e[0][1] * (-e[2][0]);
  for (int k = 0; k < 3; ++k)
    if (sign[k] == 0 || (sign[k] > 0) != (s.n[k] > 0)) s.n[k] = 0.0;  // within rounding of 0
  double crit[3];
  for (int k = 0; k < 3; ++k) crit[k] = sign[k] > 0 ? 1.0 : 0.0;
  s.d1 = s.n[0] * (crit[0] - a[0]) + s.n[1] * (crit[1] - a[1]) + s.n[2] * (crit[2] - a[2]);
  s.d2 = s.n[0] * ((1 - crit[0]) - a[0]) + s.n[1] * ((1 - crit[1]) - a[1]) +
         s.n[2] * ((1 - crit[2]) - a[2]);
  // Projection q: axes (X, Y) = (0,1) for xy [sign of n.z], (1,2) for yz [n.x], (2,0) for zx [n.y].
  const int ax[3][2] = {{0, 1}, {1, 2}, {2, 0}};
  const int normalAxis[3] = {2, 0, 1};
  for (int q = 0; q < 3; ++q) {
    const int X = ax[q][0], Y = ax[q][1];
    // An exactly degenerate projection (a segment) is tested correctly with either orientation.
    const double o = sign[normalAxis[q]] >= 0 ? 1.0 : -1.0;
    for (int i = 0; i < 3; ++i) {
      const double nx = -e[i][Y] * o, ny = e[i][X] * o;
      s.ne[q][i][0] = nx;
      s.ne[q][i][1] = ny;
      s.de[q][i] = -(nx * v[i][X] + ny * v[i][Y]) + maxd(0.0, nx) + maxd(0.0, ny);
    }
  }
  // Decision values are sums of a few products of (differences of) coordinates bounded by
  // m = 2M+2: degree 3 for the plane test, degree 2 for the edge tests. 64 ulps of 4 m^3 (m^2)
  // bounds the accumulated rounding of these short sums generously.
  const double m = 2 * M + 2;
  s.tolEdge = 256.0 * DBL_EPSILON * m * m;
  s.tolPlane = 256.0 * DBL_EPSILON * m * m * m;
  return s;
}

// Box [p, p+1]^3 (p in the same local coordinates). The caller guarantees bounding-box overlap.
CANOPY_HD inline Overlap testTriBox(const TriBoxSetup& s, const double p[3]) {
  bool ambiguous = false;
  const double np = s.n[0] * p[0] + s.n[1] * p[1] + s.n[2] * p[2];
  const double a = np + s.d1, b = np + s.d2;
  if (absd(a) <= s.tolPlane || absd(b) <= s.tolPlane) ambiguous = true;
  else if ((a > 0) == (b > 0)) return Overlap::No;  // both critical corners on one side
  const int ax[3][2] = {{0, 1}, {1, 2}, {2, 0}};
  for (int q = 0; q < 3; ++q) {
    const double px = p[ax[q][0]], py = p[ax[q][1]];
    for (int i = 0; i < 3; ++i) {
      const double f = s.ne[q][i][0] * px + s.ne[q][i][1] * py + s.de[q][i];
      if (absd(f) <= s.tolEdge) ambiguous = true;
      else if (f < 0) return Overlap::No;
    }
  }
  return ambiguous ? Overlap::Ambiguous : Overlap::Yes;
}

}  // namespace canopy::vox
