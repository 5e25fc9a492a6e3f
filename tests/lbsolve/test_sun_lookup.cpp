// The shared direction table (lattice_dirs.h) and the 32-face sun lookup (sun_lookup.h):
// the baked face table equals CGAL's convex hull of the 18 unit directions; weights are
// non-negative, sum to 1, are exact on the lattice directions, reproduce the light direction, and
// change continuously as the sun moves.
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <set>
#include <vector>

#include <CGAL/Exact_predicates_inexact_constructions_kernel.h>
#include <CGAL/Surface_mesh.h>
#include <CGAL/convex_hull_3.h>

#include "canopy/lattice_dirs.h"
#include "canopy/sun_lookup.h"

namespace {
using canopy::lattice::dir;
using canopy::lattice::kQ;

std::array<double, 3> unitDir(int m) {
  const double l = std::sqrt(double(dir(m, 0) * dir(m, 0) + dir(m, 1) * dir(m, 1) + dir(m, 2) * dir(m, 2)));
  return {dir(m, 0) / l, dir(m, 1) / l, dir(m, 2) / l};
}

// The 19-vector of weights of a lookup (index = base).
std::array<double, kQ> weightVector(const canopy::sun::Weights& w) {
  std::array<double, kQ> v{};
  for (int k = 0; k < 3; ++k) v[w.base[k]] += w.weight[k];
  return v;
}

// A face as its cyclic vertex order, rotated so the smallest index comes first.
std::array<int, 3> canonical(std::array<int, 3> f) {
  while (f[0] != std::min({f[0], f[1], f[2]})) std::rotate(f.begin(), f.begin() + 1, f.end());
  return f;
}
}  // namespace

TEST(LatticeDirs, TableInvariants) {
  using namespace canopy::lattice;
  // The documented order (lattice_dirs.h): other tools name B00..B18 by it.
  const int table[19][3] = {{0, 0, 0},  {1, 0, 0},   {-1, 0, 0}, {0, 1, 0},  {0, -1, 0},
                            {0, 0, 1},  {0, 0, -1},  {1, 1, 0},  {-1, -1, 0}, {1, -1, 0},
                            {-1, 1, 0}, {1, 0, 1},   {-1, 0, -1}, {1, 0, -1}, {-1, 0, 1},
                            {0, 1, 1},  {0, -1, -1}, {0, 1, -1}, {0, -1, 1}};
  for (int m = 0; m < kQ; ++m)
    for (int a = 0; a < 3; ++a) EXPECT_EQ(dir(m, a), table[m][a]) << m << " " << a;
  EXPECT_EQ(dir(0, 0) | dir(0, 1) | dir(0, 2), 0);
  float wsum = 0;
  std::set<std::array<int, 3>> seen;
  for (int m = 1; m < kQ; ++m) {
    const int n = std::abs(dir(m, 0)) + std::abs(dir(m, 1)) + std::abs(dir(m, 2));
    EXPECT_EQ(n, isAxial(m) ? 1 : 2) << m;
    const int o = opposite(m);
    for (int a = 0; a < 3; ++a) EXPECT_EQ(dir(o, a), -dir(m, a)) << m;
    EXPECT_EQ(opposite(o), m);
    EXPECT_EQ(indexOf(dir(m, 0), dir(m, 1), dir(m, 2)), m);
    EXPECT_FLOAT_EQ(length(m) * length(m), float(n));
    seen.insert({dir(m, 0), dir(m, 1), dir(m, 2)});
    wsum += weight(m);
  }
  EXPECT_EQ(seen.size(), 18u);
  EXPECT_NEAR(wsum, 1.0f, 1e-6f);
  EXPECT_EQ(indexOf(1, 1, 1), -1);
  EXPECT_STREQ(baseName(7), "B07");
}

// Recomputes the hull with CGAL and checks the baked face table: same 32 faces, same outward
// (counter-clockwise) vertex order.
TEST(SunLookup, FaceTableIsTheConvexHullOfTheUnitDirections) {
  using K = CGAL::Exact_predicates_inexact_constructions_kernel;
  using Point = K::Point_3;
  using Mesh = CGAL::Surface_mesh<Point>;
  std::vector<Point> pts;
  for (int m = 1; m < kQ; ++m) {
    auto u = unitDir(m);
    pts.emplace_back(u[0], u[1], u[2]);
  }
  Mesh hull;
  CGAL::convex_hull_3(pts.begin(), pts.end(), hull);
  ASSERT_EQ(hull.number_of_faces(), 32u);
  auto indexOfPoint = [&](const Point& p) {
    for (int m = 1; m < kQ; ++m) {
      auto u = unitDir(m);
      if (std::abs(p.x() - u[0]) + std::abs(p.y() - u[1]) + std::abs(p.z() - u[2]) < 1e-12) return m;
    }
    return -1;
  };
  std::set<std::array<int, 3>> cgalFaces, bakedFaces;
  for (auto f : hull.faces()) {
    std::array<int, 3> tri{};
    int v = 0;
    for (auto vd : CGAL::vertices_around_face(hull.halfedge(f), hull)) {
      ASSERT_LT(v, 3);
      tri[v++] = indexOfPoint(hull.point(vd));
      ASSERT_GT(tri[v - 1], 0);
    }
    cgalFaces.insert(canonical(tri));  // CGAL orients faces outward (counter-clockwise)
  }
  for (int f = 0; f < canopy::sun::kFaces; ++f) {
    std::array<int, 3> tri{canopy::sun::faceVertex(f, 0), canopy::sun::faceVertex(f, 1),
                           canopy::sun::faceVertex(f, 2)};
    bakedFaces.insert(canonical(tri));
    // det(c_a, c_b, c_c) > 0: outward orientation, which faceBarycentric relies on.
    const int a = tri[0], b = tri[1], c = tri[2];
    const int det = dir(a, 0) * (dir(b, 1) * dir(c, 2) - dir(b, 2) * dir(c, 1)) -
                    dir(a, 1) * (dir(b, 0) * dir(c, 2) - dir(b, 2) * dir(c, 0)) +
                    dir(a, 2) * (dir(b, 0) * dir(c, 1) - dir(b, 1) * dir(c, 0));
    EXPECT_GT(det, 0) << "face " << f;
  }
  EXPECT_EQ(bakedFaces.size(), 32u);
  EXPECT_EQ(cgalFaces, bakedFaces);
}

TEST(SunLookup, ExactOnTheLatticeDirections) {
  for (int m = 1; m < kQ; ++m) {
    const auto u = unitDir(m);
    for (float scale : {1.0f, 0.0f}) {  // integer vector, then normalised vector
      const float x = scale ? float(dir(m, 0)) : float(u[0]);
      const float y = scale ? float(dir(m, 1)) : float(u[1]);
      const float z = scale ? float(dir(m, 2)) : float(u[2]);
      canopy::sun::Weights w;
      ASSERT_TRUE(canopy::sun::lookup(x, y, z, w)) << m;
      auto v = weightVector(w);
      for (int j = 0; j < kQ; ++j) EXPECT_EQ(v[j], j == m ? 1.0 : 0.0) << "dir " << m << " base " << j;
    }
  }
}

TEST(SunLookup, SunOverheadLightsTheDownwardBase) {
  canopy::sun::Weights w;
  ASSERT_TRUE(canopy::sun::lookupToSun(0, 1, 0, w));  // sun at the zenith, light travels -y
  EXPECT_EQ(weightVector(w)[4], 1.0);
  EXPECT_EQ(canopy::lattice::dir(4, 1), -1);
}

TEST(SunLookup, RejectsDegenerateDirections) {
  canopy::sun::Weights w;
  EXPECT_FALSE(canopy::sun::lookup(0, 0, 0, w));
  EXPECT_EQ(w.weight[0] + w.weight[1] + w.weight[2], 0.f);
  EXPECT_FALSE(canopy::sun::lookup(NAN, 0, 1, w));
  EXPECT_FALSE(canopy::sun::lookup(INFINITY, 0, 1, w));
}

// Weights are barycentric: non-negative, sum to 1, and sum_k w_k u_k lies on the ray d (so the
// hit point, hence the light direction, is reproduced).
TEST(SunLookup, WeightsAreBarycentricOnTheRay) {
  uint32_t s = 12345;
  auto rnd = [&] { s = s * 1664525u + 1013904223u; return (s >> 8) / 16777216.0 * 2 - 1; };
  for (int t = 0; t < 20000; ++t) {
    const double dx = rnd(), dy = rnd(), dz = rnd();
    canopy::sun::Weights w;
    ASSERT_TRUE(canopy::sun::lookup(float(dx), float(dy), float(dz), w));
    double sum = 0, p[3] = {0, 0, 0};
    for (int k = 0; k < 3; ++k) {
      EXPECT_GE(w.weight[k], 0.f);
      sum += w.weight[k];
      const auto u = unitDir(w.base[k]);
      for (int a = 0; a < 3; ++a) p[a] += w.weight[k] * u[a];
    }
    EXPECT_NEAR(sum, 1.0, 1e-6);
    // p parallel to d and on the same side: |p x d| ~ 0, p . d > 0.
    const double cx = p[1] * dz - p[2] * dy, cy = p[2] * dx - p[0] * dz, cz = p[0] * dy - p[1] * dx;
    const double dn = std::sqrt(dx * dx + dy * dy + dz * dz);
    EXPECT_LT(std::sqrt(cx * cx + cy * cy + cz * cz) / dn, 1e-5);
    EXPECT_GT(p[0] * dx + p[1] * dy + p[2] * dz, 0.0);
  }
}

// No popping: along a 1000-step spiral from pole to pole (5 turns, every face visited) the 19
// weights move by at most 0.1 (L1) per step. The step is ~0.024 rad; barycentric coordinates of a
// face ~0.7 wide change by ~0.024/0.6 per coordinate, so 0.1 leaves room for three coordinates.
// A discontinuous scheme (nearest direction, or greedy selection as in [12]) jumps by up to 2.
TEST(SunLookup, ContinuousAlongA1000StepSweep) {
  const int n = 1000;
  std::array<double, kQ> prev{};
  std::set<int> faces;
  double worst = 0;
  for (int i = 0; i < n; ++i) {
    const double t = double(i) / (n - 1);
    const double theta = 0.02 + t * (M_PI - 0.04), phi = 5 * 2 * M_PI * t + 0.3;
    const double x = std::sin(theta) * std::cos(phi), y = std::cos(theta), z = std::sin(theta) * std::sin(phi);
    canopy::sun::Weights w;
    ASSERT_TRUE(canopy::sun::lookup(float(x), float(y), float(z), w));
    faces.insert(w.face);
    auto v = weightVector(w);
    if (i > 0) {
      double d = 0;
      for (int j = 0; j < kQ; ++j) d += std::abs(v[j] - prev[j]);
      worst = std::max(worst, d);
    }
    prev = v;
  }
  EXPECT_LT(worst, 0.1);
  EXPECT_GE(faces.size(), 28u);  // the sweep really crosses (nearly) every face
}
