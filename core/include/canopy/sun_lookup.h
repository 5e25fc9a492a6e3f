// sun_lookup.h: sun direction -> at most three base solutions and their barycentric weights.
//
// Dissertation §4.1 (fig. 4.3) and §4.2: the 18 unit lattice directions c_m/|c_m| (m = 1..18, the
// order of lattice_dirs.h) are the vertices of a convex polyhedron with 32 triangular faces:
// 24 faces of one axial and two diagonal directions (a square pyramid over each axis) and 8 faces
// of three diagonal directions (one per octant). A ray from the origin along the light direction
// hits one face (a, b, c); the light is split over B_a, B_b, B_c with the barycentric coordinates
// of the hit point, which are non-negative and sum to 1. Along a shared edge the two faces give
// the same weights, so the weights are continuous as the sun moves (no popping), and for a sun
// exactly along c_j the whole weight goes to B_j.
//
// Direction convention: pass the direction the light TRAVELS (from the sun into the scene, i.e.
// minus the "to sun" vector), in the lattice's index axes (= model axes; +y up). Base B_j holds the
// steady state for photons entering along +c_j, so a sun straight overhead (light travelling -y)
// maps to B04 = (0,-1,0) with weight 1.
//
// The face table below was produced from the convex hull of the 18 unit directions; the test
// tests/lbsolve/test_sun_lookup.cpp recomputes that hull with CGAL and checks the table (vertex
// sets and outward orientation) against it. CANOPY_HD: the GPU player calls the same code.
#pragma once

#include "canopy/hd.h"
#include "canopy/lattice_dirs.h"

namespace canopy::sun {

constexpr int kFaces = 32;

// Face f's vertex v (a direction index 1..18). Vertices are ordered counter-clockwise seen from
// outside, i.e. det(c_a, c_b, c_c) > 0.
CANOPY_HD constexpr int faceVertex(int f, int v) {
  constexpr int kF[kFaces][3] = {
      {1, 7, 11},  {1, 13, 7},  {1, 11, 9},  {1, 9, 13},    // pyramid over +x
      {2, 12, 8},  {2, 8, 14},  {2, 10, 12}, {2, 14, 10},   // pyramid over -x
      {3, 15, 7},  {3, 7, 17},  {3, 10, 15}, {3, 17, 10},   // pyramid over +y
      {4, 8, 16},  {4, 18, 8},  {4, 16, 9},  {4, 9, 18},    // pyramid over -y
      {5, 11, 15}, {5, 18, 11}, {5, 15, 14}, {5, 14, 18},   // pyramid over +z
      {6, 16, 12}, {6, 12, 17}, {6, 13, 16}, {6, 17, 13},   // pyramid over -z
      {7, 15, 11}, {7, 13, 17}, {8, 12, 16}, {8, 18, 14},   // octant faces (+,+,+) (+,+,-) (-,-,-) (-,-,+)
      {9, 11, 18}, {9, 16, 13}, {10, 17, 12}, {10, 14, 15}, // (+,-,+) (+,-,-) (-,+,-) (-,+,+)
  };
  return kF[f][v];
}

struct Weights {
  int base[3] = {0, 0, 0};          // base solution indices (1..18); unused slots hold 0
  float weight[3] = {0.f, 0.f, 0.f}; // >= 0, summing to 1 (all 0 when the lookup failed)
  int face = -1;                     // the face hit, -1 for a zero or non-finite direction
};

// The barycentric coordinates of the ray d on face f, in the unit-vector basis (they may be
// negative when the ray misses the face). Computed in the integer basis c_m (exact for integer
// d) and rescaled by |c_m|, because the polyhedron's vertices are the unit vectors c_m/|c_m|.
// Returns false when d points away from the face's cone (no intersection on that side).
CANOPY_HD inline bool faceBarycentric(int f, float dx, float dy, float dz, float out[3]) {
  float k[3];
  CANOPY_UNROLL
  for (int v = 0; v < 3; ++v) {
    const int b = faceVertex(f, (v + 1) % 3), c = faceVertex(f, (v + 2) % 3);
    using lattice::dir;
    // (c_b x c_c) . d: the cone coefficient of vertex v times det(c_a, c_b, c_c) > 0.
    const float nx = float(dir(b, 1) * dir(c, 2) - dir(b, 2) * dir(c, 1));
    const float ny = float(dir(b, 2) * dir(c, 0) - dir(b, 0) * dir(c, 2));
    const float nz = float(dir(b, 0) * dir(c, 1) - dir(b, 1) * dir(c, 0));
    k[v] = (nx * dx + ny * dy + nz * dz) * lattice::length(faceVertex(f, v));
  }
  const float sum = k[0] + k[1] + k[2];
  if (!(sum > 0.f)) return false;
  for (int v = 0; v < 3; ++v) out[v] = k[v] / sum;
  return true;
}

// The lookup: which face the light direction (dx, dy, dz) (need not be normalised) passes
// through, and the weights of its three bases. Picks the face whose smallest barycentric
// coordinate is largest (the face containing d; on a shared edge or vertex the first such face,
// whose weights equal its neighbour's there), then clamps rounding-level negatives to 0 and
// renormalises. Returns false (weights all 0) for a zero or non-finite direction.
CANOPY_HD inline bool lookup(float dx, float dy, float dz, Weights& w) {
  w = Weights();
  if (!(dx * dx + dy * dy + dz * dz > 0.f) || !(dx * dx + dy * dy + dz * dz < 3.0e38f))
    return false;
  float best = -3.0e38f;
  float bary[3] = {0.f, 0.f, 0.f};
  for (int f = 0; f < kFaces; ++f) {
    float b[3];
    if (!faceBarycentric(f, dx, dy, dz, b)) continue;
    const float m = b[0] < b[1] ? (b[0] < b[2] ? b[0] : b[2]) : (b[1] < b[2] ? b[1] : b[2]);
    if (m > best) {
      best = m;
      w.face = f;
      bary[0] = b[0], bary[1] = b[1], bary[2] = b[2];
    }
  }
  if (w.face < 0) return false;
  float sum = 0.f;
  for (int v = 0; v < 3; ++v) {
    bary[v] = bary[v] > 0.f ? bary[v] : 0.f;
    sum += bary[v];
  }
  for (int v = 0; v < 3; ++v) {
    w.base[v] = faceVertex(w.face, v);
    w.weight[v] = bary[v] / sum;
  }
  return true;
}

// Convenience for callers holding the direction TO the sun: light travels the other way.
CANOPY_HD inline bool lookupToSun(float sx, float sy, float sz, Weights& w) {
  return lookup(-sx, -sy, -sz, w);
}

}  // namespace canopy::sun
