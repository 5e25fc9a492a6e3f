// pull_stream.h: the CUDA backend's "pull" scheme, the push update of collide.h reorganised so
// that every store is aligned and every warp's loads are contiguous, written as CANOPY_HD
// functions so that the CPU tests run the very same index arithmetic (tests/lbsolve/test_collide.cpp
// compares it with the reference push update bit for bit, iteration by iteration).
//
// Why (docs/performance.md, 'The pull scheme'): the push update over every node reaches 53-59 % of
// the copy bandwidth on an H100 and 45-56 % on an H200, and bench_lbsolve_streams shows that its memory traffic alone,
// without the collision, does the same (58 % at 128^3, 68 % at 256^3 on an H200): shifted stores in
// structure-of-arrays layout are the limit. Pull (shifted loads, aligned stores) in an
// array-of-structures-of-arrays layout (tiles of 32 nodes along x, the 19 directions of a tile
// contiguous) moved the same bytes at 73 % and 84 %.
//
// What is stored: the push state holds the values ARRIVING at each node (f_m(r, t)); the pull state
// holds each node's values LEAVING it after its collision (post_m(r, t) = collide(f(r, t))_m). The
// arrivals are then read from the neighbours, f_m(r, t+1) = post_m(r - c_m, t), collided, and the
// result stored at r itself. With the same arrivals collide() computes the same bits, so after t
// steps the arrivals a pull step reads are exactly the push state after t steps.
// - Interior nodes start at 0 (collide(0) = 0, so post = 0 too); boundary nodes hold the post values
//   of their fixed boundary values, the same at every iteration (written once per solve into both
//   buffers, pullBoundaryNode) and never changed (pullNode rewrites those at the ends of interior
//   rows with the values they hold, for whole-sector stores).
// - The totals of iteration t (gather, residual) are sums of the arrivals: pullArrivalTotal() over
//   the state before the last step (the push state's nodeTotal order of additions); a boundary
//   node's total is boundaryTotal().
#pragma once
#include <cstdint>

#include "collide.h"

namespace canopy::lb {

// Tiles of 32 nodes along x; x is padded to a multiple of 32 (padding slots are never read).
constexpr int kPullTile = 32;

struct PullLayout {
  Dims d;
  int nxp;  // nx rounded up to a multiple of kPullTile
};

inline PullLayout pullLayout(const Dims& d) { return {d, (d.nx + kPullTile - 1) / kPullTile * kPullTile}; }
// Floats of one state buffer.
inline int64_t pullStateFloats(const PullLayout& L) { return int64_t(L.nxp) * L.d.ny * L.d.nz * kQ; }

// Slot of direction m of node (x, y, z).
CANOPY_HD CANOPY_FORCEINLINE int64_t pullSlot(const PullLayout& L, int m, int x, int y, int z) {
  const int64_t p = (int64_t(z) * L.d.ny + y) * L.nxp + x;
  return ((p / kPullTile) * kQ + m) * kPullTile + p % kPullTile;
}

// The arrivals f at interior node (x, y, z): the neighbours' post values in `in`. reach 0: the
// node's own post values instead (one load per direction either way: the address is selected).
CANOPY_HD CANOPY_FORCEINLINE void pullLoad(const PullLayout& L, const float* in, int x, int y, int z, float f[kQ],
                                           int reach = 1) {
  CANOPY_UNROLL
  for (int m = 0; m < kQ; ++m)
    f[m] = in[pullSlot(L, m, x - reach * lattice::dir(m, 0), y - reach * lattice::dir(m, 1), z - reach * lattice::dir(m, 2))];
}

// Collide the arrivals f of interior node (x, y, z), coded density `coded` (of kind Kind, or any),
// and store its post values at the node itself in `out`. f is modified (collide.h).
template <int Kind = kAnyKind>
CANOPY_HD CANOPY_FORCEINLINE void pullCollideStore(const OmegaSet& om, const PullLayout& L, float coded, float f[kQ],
                                                   float* out, int x, int y, int z) {
  float post[kQ];
  collide<Kind>(om, coded, f, post);
  CANOPY_UNROLL
  for (int m = 0; m < kQ; ++m) out[pullSlot(L, m, x, y, z)] = post[m];
}

// Lane x (< L.nxp) of the pull kernel's row (y, z), one iteration, from the post values `in` to
// `out`. An interior node: its arrivals from the neighbours, then its density (read after the 19
// loads, so that it does not delay them), the collision of its kind and the store at the node. A
// boundary node or padding slot of an interior row runs the same loads and stores on its own slots,
// through the wood branch with density 0 (the identity: no f_0 zeroing, post = f bit for bit), so
// that every warp of the row writes whole 32-byte sectors without a second memory round trip (a
// sector written in part is read from DRAM first: docs/performance.md, 'Whole sectors'). Boundary
// rows and planes are not written at all.
CANOPY_HD CANOPY_FORCEINLINE void pullNode(const OmegaSet& om, const PullLayout& L, const float* coded, const float* in,
                                           float* out, int x, int y, int z) {
  const bool inside = L.d.interior(x, y, z);
  if (!inside && (y < 1 || z < 1 || y >= L.d.ny - 1 || z >= L.d.nz - 1 || x >= L.nxp)) return;
  float f[kQ];
  pullLoad(L, in, x, y, z, f, inside ? 1 : 0);
  const float c = inside ? coded[L.d.index(x, y, z)] : -0.f;
  if (inside && c >= 0.f)
    pullCollideStore<kLeafKind>(om, L, c, f, out, x, y, z);
  else
    pullCollideStore<kWoodKind>(om, L, c, f, out, x, y, z);
}

// Boundary node (x, y, z): its post values, the collision of the fixed boundary values (what the
// push update sends from it at every iteration), into `state`.
CANOPY_HD CANOPY_FORCEINLINE void pullBoundaryNode(const OmegaSet& om, const PullLayout& L, const float boundary[kQ],
                                                   float coded, float* state, int x, int y, int z) {
  float f[kQ], post[kQ];
  CANOPY_UNROLL
  for (int m = 0; m < kQ; ++m) f[m] = boundary[m];
  collide(om, coded, f, post);
  CANOPY_UNROLL
  for (int m = 0; m < kQ; ++m) state[pullSlot(L, m, x, y, z)] = post[m];
}

// The total of the arrivals at node (x, y, z) when `state` holds the post values of the iteration
// before (sum over m ascending, as nodeTotal); fixedTotal (boundaryTotal) at a boundary node.
CANOPY_HD CANOPY_FORCEINLINE float pullArrivalTotal(const PullLayout& L, const float* state, float fixedTotal,
                                                    int x, int y, int z) {
  if (!L.d.interior(x, y, z)) return fixedTotal;
  float s = 0.f;
  CANOPY_UNROLL
  for (int m = 0; m < kQ; ++m)
    s += state[pullSlot(L, m, x - lattice::dir(m, 0), y - lattice::dir(m, 1), z - lattice::dir(m, 2))];
  return s;
}

}  // namespace canopy::lb
