// lattice_dirs.h: the D3Q19 direction table of the lattice-Boltzmann lighting model.
//
// Dissertation §2.2 (fig. 2.1): 18 directions from projecting the 24 4D points (±1,0,0,±1)...
// onto 3D, plus the rest direction c_0 = (0,0,0) that holds absorbed light. Every Canopy tool
// names the base solutions B00..B18 by THIS order:
//
//   index  c_m            kind      index  c_m            kind
//     0    ( 0, 0, 0)     rest        10   (-1, 1, 0)     diagonal
//     1    (+1, 0, 0)     axial       11   (+1, 0,+1)     diagonal
//     2    (-1, 0, 0)     axial       12   (-1, 0,-1)     diagonal
//     3    ( 0,+1, 0)     axial       13   (+1, 0,-1)     diagonal
//     4    ( 0,-1, 0)     axial       14   (-1, 0,+1)     diagonal
//     5    ( 0, 0,+1)     axial       15   ( 0,+1,+1)     diagonal
//     6    ( 0, 0,-1)     axial       16   ( 0,-1,-1)     diagonal
//     7    (+1,+1, 0)     diagonal    17   ( 0,+1,-1)     diagonal
//     8    (-1,-1, 0)     diagonal    18   ( 0,-1,+1)     diagonal
//     9    (+1,-1, 0)     diagonal
//
// Invariants (checked in tests/lbsolve): opposite directions are adjacent pairs (1,2), (3,4), ...,
// (17,18), so opposite(m) = m + 1 for odd m and m - 1 for even m > 0; axial directions 1..6 carry
// double weight. The weights w_m are those of Ω's rows (eq. 2.16-2.17): 1/12 axial, 1/24 diagonal,
// summing to 1 over m = 1..18. Coordinates are lattice index axes (i, j, k) = (x, y, z); in model
// space +y is up (glTF).
#pragma once

#include "canopy/hd.h"


namespace canopy::lattice {

constexpr int kQ = 19;          // directions including the rest direction c_0
constexpr int kDirections = 18; // moving directions c_1..c_18

// c_m's component along axis (0 x, 1 y, 2 z), for m = 0..18. The table above is packed as
// 2 bits per direction (component + 1) in one 64-bit constant per axis, so that the function is
// plain arithmetic: cheap for a run-time m on the host, and usable in device code without a table
// in memory (tests/lbsolve/test_sun_lookup.cpp checks it against the table literally).
CANOPY_HD constexpr int dir(int m, int axis) {
  const unsigned long long pack = axis == 0 ? 0x1548889549ull : (axis == 1 ? 0x895609495ull : 0x20a0954955ull);
  return int((pack >> (2 * m)) & 3u) - 1;
}

CANOPY_HD constexpr bool isAxial(int m) { return m >= 1 && m <= 6; }

// c_i . c_j (integer: |c|^2 is 1 for axial, 2 for diagonal directions).
CANOPY_HD constexpr int dot(int i, int j) { return dir(i, 0) * dir(j, 0) + dir(i, 1) * dir(j, 1) + dir(i, 2) * dir(j, 2); }

// Index of -c_m (0 for the rest direction).
CANOPY_HD constexpr int opposite(int m) { return m == 0 ? 0 : ((m & 1) ? m + 1 : m - 1); }

// Weight of row m in Ω (eq. 2.16-2.17): 1/12 axial, 1/24 diagonal; 0 for the rest direction.
CANOPY_HD constexpr float weight(int m) {
  return m == 0 ? 0.0f : (isAxial(m) ? 1.0f / 12.0f : 1.0f / 24.0f);
}

// |c_m|: 1 for axial, sqrt(2) for diagonal, 0 for rest.
CANOPY_HD constexpr float length(int m) {
  return m == 0 ? 0.0f : (isAxial(m) ? 1.0f : 1.41421356237309504880f);
}

// Index of the direction (x, y, z) with components in {-1, 0, 1} and at most two non-zero, or -1.
CANOPY_HD constexpr int indexOf(int x, int y, int z) {
  for (int m = 0; m < kQ; ++m)
    if (dir(m, 0) == x && dir(m, 1) == y && dir(m, 2) == z) return m;
  return -1;
}

// The grid name of base solution m: "B00".."B18".
inline const char* baseName(int m) {
  static const char* const kNames[kQ] = {"B00", "B01", "B02", "B03", "B04", "B05", "B06",
                                         "B07", "B08", "B09", "B10", "B11", "B12", "B13",
                                         "B14", "B15", "B16", "B17", "B18"};
  return (m >= 0 && m < kQ) ? kNames[m] : "";
}

}  // namespace canopy::lattice
