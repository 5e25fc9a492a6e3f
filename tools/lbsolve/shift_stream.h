// shift_stream.h: streaming by index shift, the CUDA backend's default scheme ("shift"), written
// as CANOPY_HD functions so that the CPU tests run the very same index arithmetic
// (tests/lbsolve/test_collide.cpp compares it with the reference push update bit for bit).
//
// The push update (collide.h) moves every value of every node each iteration, although at an empty
// node (rho = 0) the collision is the identity: out = f bit for bit (collideKind's pass-through),
// and f_0 of an empty interior node is always 0 (it starts at 0 and only the node itself could feed
// it, c_0 = 0). Only the streaming changes those values, and streaming can be done without moving
// data: direction m's values live in a ring of the n = nx*ny*nz node slots, and node p's value of
// direction m at iteration t lies in slot
//     shifted(p, off_m(t)) = (p + off_m(t)) mod n,    off_m(t) = -t * s_m mod n,
// where s_m = c_mx + nx * (c_my + ny * c_mz) is the linear index step of c_m. A value left in slot
// q at iteration t belongs to node q - off_m(t) at t, and to node q - off_m(t+1) = that node + c_m
// at t + 1: it has streamed by c_m with no memory traffic. An iteration then only has to
//   (a) collide, in place, the interior nodes with rho != 0 (occupied nodes; read 19 values, write
//       19 values in their own slots; distinct nodes own distinct slots, so threads never race), and
//   (b) at every boundary node b, write the value b sends into the interior for each direction m
//       with b + c_m interior: the m-th output of b's collision of the fixed boundary values (the
//       push update's source at a boundary node, which is never written and always holds them).
// Every other slot already holds the right value: an empty interior node's slot for m holds what
// its neighbour r - c_m produced at t - 1 (interior r - c_m: collided or itself passed through;
// boundary r - c_m: written by (b)). For an interior target p, p - s_m is the in-box neighbour
// r - c_m, so the ring's wrap-around only ever moves values into boundary slots, which nothing
// reads: boundary nodes' light is the fixed boundary values (their total is boundaryTotal()).
// The state starts as all zeros (interior nodes start at 0; boundary slots are never read).
//
// Cost per iteration: O(occupied + boundary nodes) instead of O(all nodes); a plant lattice is
// mostly empty (oak_medium at 128^3: 2.9% of the nodes). The residual (solver.h) still needs the
// total of every node at two iterations: a full pass, every checkEvery iterations.
#pragma once
#include <cstdint>

#include "collide.h"

namespace canopy::lb {

// Slots are 32-bit: the scheme requires n < 2^31 nodes (a 1290^3 lattice; at 19 floats per node
// that is far beyond one GPU's memory). The CUDA solver checks it.
constexpr int64_t kMaxShiftNodes = (int64_t(1) << 31) - 1;

struct ShiftOffsets {
  uint32_t off[kQ];  // slot of node p for direction m: shifted(p, off[m], n); 0 <= off[m] < n
};

// The linear index step of lattice direction m.
CANOPY_HD CANOPY_FORCEINLINE int64_t linearStep(const Dims& d, int m) {
  return lattice::dir(m, 0) + int64_t(d.nx) * (lattice::dir(m, 1) + int64_t(d.ny) * lattice::dir(m, 2));
}

// The offsets after t iterations (t >= 0). Precondition: 0 < d.count() <= kMaxShiftNodes.
inline ShiftOffsets shiftOffsets(const Dims& d, int64_t t) {
  ShiftOffsets s;
  const int64_t n = d.count();
  for (int m = 0; m < kQ; ++m) {
    // t mod n < 2^31 and |s_m| <= nx*ny + nx + 1 < 2^31 keep the product inside int64.
    const int64_t o = -((t % n) * linearStep(d, m)) % n;
    s.off[m] = uint32_t(o < 0 ? o + n : o);
  }
  return s;
}

// (p + off) mod n for p, off < n < 2^31 (the sum fits in 32 bits).
CANOPY_HD CANOPY_FORCEINLINE uint32_t shifted(uint32_t p, uint32_t off, uint32_t n) {
  const uint32_t q = p + off;
  return q >= n ? q - n : q;
}

// Returns v; on the GPU the compiler must then assume it is a new value (an empty asm statement,
// no instruction). shiftCollideNode recomputes its 19 store addresses from such a copy of the
// node index instead of keeping the 19 load addresses live across the collision: 38 fewer
// registers, more resident threads (docs/performance.md, 'Registers of the shift step').
CANOPY_HD CANOPY_FORCEINLINE uint32_t opaqueCopy(uint32_t v) {
#if defined(__CUDA_ARCH__)
  asm volatile("" : "+r"(v));
#endif
  return v;
}

// (a): collide occupied interior node p (coded density `coded` != 0) in place. With totalBefore,
// also stores the node's total before the collision (nodeTotal's order of additions): the
// residual's previous total of an occupied node, whose slots the collision overwrites.
template <int Kind = kAnyKind>
CANOPY_HD CANOPY_FORCEINLINE void shiftCollideNode(const OmegaSet& om, const ShiftOffsets& s, int64_t n,
                                                   float coded, int64_t p, float* state,
                                                   float* totalBefore = nullptr) {
  const uint32_t q = uint32_t(p), nn = uint32_t(n);
  float f[kQ], post[kQ];
  CANOPY_UNROLL
  for (int m = 0; m < kQ; ++m) f[m] = state[m * n + shifted(q, s.off[m], nn)];
  if (totalBefore) {
    float t = 0.f;
    CANOPY_UNROLL
    for (int m = 0; m < kQ; ++m) t += f[m];
    *totalBefore = t;
  }
  collide<Kind>(om, coded, f, post);
  const uint32_t r = opaqueCopy(q);
  CANOPY_UNROLL
  for (int m = 0; m < kQ; ++m) state[m * n + shifted(r, s.off[m], nn)] = post[m];
}

// (b): boundary node (x, y, z) with coded density `coded` writes what it sends into the interior:
// the outputs of its collision of the fixed boundary values. Empty = true is the caller's promise
// that coded == 0, where that collision is the pass-through (bit for bit): the boundary values
// themselves are written, with no collision at all.
template <bool Empty = false>
CANOPY_HD CANOPY_FORCEINLINE void shiftBoundaryNode(const OmegaSet& om, const Dims& d, const float boundary[kQ],
                                                    const ShiftOffsets& s, float coded, int x, int y, int z,
                                                    float* state) {
  const int64_t n = d.count(), p = d.index(x, y, z);
  float post[kQ];
  if constexpr (Empty) {
    CANOPY_UNROLL
    for (int m = 0; m < kQ; ++m) post[m] = boundary[m];
  } else {
    float f[kQ];
    CANOPY_UNROLL
    for (int m = 0; m < kQ; ++m) f[m] = boundary[m];
    collide(om, coded, f, post);
  }
  CANOPY_UNROLL
  for (int m = 0; m < kQ; ++m)
    if (d.interior(x + lattice::dir(m, 0), y + lattice::dir(m, 1), z + lattice::dir(m, 2)))
      state[m * n + shifted(uint32_t(p), s.off[m], uint32_t(n))] = post[m];
}

// The total site density of interior node p (nodeTotal of collide.h, same order of additions).
// The residual needs the totals of two consecutive iterations t-1 and t. An iteration writes only
// the slots of occupied interior nodes and of boundary nodes (at the offsets of t-1), so after it
// an empty interior node's total at t-1 is still shiftNodeTotal(state, n, shiftOffsets(d, t-1), p);
// an occupied node's is the one shiftCollideNode recorded. One pass over the state then gives
// both (the slots read at t-1 are the ones a neighbour reads at t: mostly cache hits).
CANOPY_HD CANOPY_FORCEINLINE float shiftNodeTotal(const float* state, int64_t n, const ShiftOffsets& s, int64_t p) {
  float t = 0.f;
  CANOPY_UNROLL
  for (int m = 0; m < kQ; ++m) t += state[m * n + shifted(uint32_t(p), s.off[m], uint32_t(n))];
  return t;
}

}  // namespace canopy::lb
