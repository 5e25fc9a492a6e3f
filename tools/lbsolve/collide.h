// collide.h: the lattice-Boltzmann lighting update of one node, written once for CPU and CUDA.
//
// The model is the dissertation's (§2.2, §4.1; listing 5.1 for the order of operations):
//   f_m(r + c_m, t+1) = max(0, f_m(r,t) + (Omega (p(r) . f(r,t)))_m),   m = 0..18,
// with p_m(r) the probability that light moving along c_m interacts at node r: rho(r) in the
// dissertation (linear), 1 - exp(-sigma rho(r) |c_m|) by default (Beer-Lambert; OmegaSet),
// where Omega is the 19x19 collision matrix of eq. 2.15-2.17 with sigma_s scaled by the normalised
// Henyey-Greenstein phase function pn_ij(g) of eq. 4.1-4.2. At leaf ("green") nodes f_0 (the
// absorbed light) is zeroed before the update; wood ("brown") nodes use their own Omega (g = -1)
// and keep f_0. Only interior nodes are written; the outer layer keeps its fixed boundary values.
//
// Storage (both backends): structure of arrays, state[m * n + idx] with idx = (z*ny + y)*nx + x,
// so that consecutive threads (x) touch consecutive addresses for every m. The per-node "coded"
// density is rho for leaf/empty nodes and -rho for wood nodes (the dissertation's encoding).
//
// Invariants (tests/lbsolve/test_collide.cpp): every column of Omega sums to 0 (a step conserves
// energy where sigma_a = 0); rho = 0 is a pure pass-through; sigma_a = 0 with g = 1 is a pass-through;
// in every row the entries of one class of directions (axial or diagonal c_j, and c_i . c_j) are
// equal (omegaIsClassStructured), which the grouped product relies on.
#pragma once
#include <cmath>
#include <cstdint>
#include <cstring>

#include "canopy/hd.h"
#include "canopy/lattice_dirs.h"
#include "omega_product.h"

namespace canopy::lb {

using lattice::kQ;

// Omega for one colour channel, column-major: col[kind][j][i] = Omega_ij, kind 0 = leaf, 1 = wood.
// On the CPU each entry is broadcast to 8 lanes (nodes); on the GPU every index is a compile-time
// constant after unrolling and the struct is a kernel parameter, i.e. in constant memory.
// The interaction of a node with the light passing through it (interactionProbabilities):
//   beerLambert != 0: direction m interacts with probability p_m = 1 - exp(-tau[class] * rho), the
//     Beer-Lambert law of the player's medium (extinction sigma per lattice cell at density 1):
//     tau[0] = sigma for the rest and axial directions (one cell per step), tau[1] = sigma * sqrt 2
//     for the diagonal ones (sqrt 2 cells per step), so the unscattered beam along any lattice
//     direction falls as exp(-sigma * rho * length in cells), as the player's direct sun does;
//   beerLambert == 0: p_m = rho for every m, the dissertation's linear collision (eq. 2.14).
struct OmegaSet {
  float col[2][kQ][kQ];
  float tau[2];         // Beer-Lambert optical depth per step at density 1: {axial, diagonal}
  int32_t beerLambert;  // 1: p_m = 1 - exp(-tau rho); 0: p_m = rho (the dissertation's)
  float sigmaT;         // sigma_a + sigma_s: what an interaction removes from its direction (beam.h)
};

// exp(-x) for 0 <= x (x > 87 gives 0) from IEEE additions and multiplications alone (no FMA, no
// library call): the CPU and the GPU compute the same bits, which the solvers' bit-for-bit
// agreement needs (a device expf differs from the host's in the last ulp). e^-x = 2^-n e^y with
// n = round(x log2 e) and y = n ln 2 - x in [-0.347, 0.347], formed with ln 2 split in two
// (Cody-Waite: n * kLn2Hi is exact for n < 2^12) so that y keeps its precision for large x;
// e^y by its Taylor series to degree 8; 2^-n built from its exponent bits.
CANOPY_HD CANOPY_FORCEINLINE float lbExpNeg(float x) {
  if (!(x < 87.0f)) return 0.0f;
  const float n = floorf(x * 1.44269504088896341f + 0.5f);
  const float y = (n * 0.693145751953125f - x) + n * 1.42860682030941723e-6f;
  float e = 2.48015873015873016e-5f;                // 1/8!
  e = e * y + 1.98412698412698413e-4f;              // 1/7!
  e = e * y + 1.38888888888888889e-3f;
  e = e * y + 8.33333333333333333e-3f;
  e = e * y + 4.16666666666666667e-2f;
  e = e * y + 1.66666666666666667e-1f;
  e = e * y + 0.5f;
  e = e * y + 1.0f;
  e = e * y + 1.0f;
  const int k = 127 - int(n);  // 2^-n as a float: exponent field 127 - n (n <= 126 here)
  if (k <= 0) return 0.0f;
  const uint32_t bits = uint32_t(k) << 23;
  float scale;
#if defined(__CUDA_ARCH__)
  scale = __uint_as_float(bits);
#else
  static_assert(sizeof(float) == sizeof(uint32_t), "float is 32 bits");
  std::memcpy(&scale, &bits, sizeof scale);
#endif
  return e * scale;
}

// The interaction probabilities of L nodes of density rho[l] (OmegaSet): p[0][l] for the rest and
// axial directions, p[1][l] for the diagonal ones.
template <int L>
CANOPY_HD CANOPY_FORCEINLINE void interactionProbabilities(const OmegaSet& om, const float rho[L], float p[2][L]) {
  for (int l = 0; l < L; ++l) {
    if (om.beerLambert) {
      p[0][l] = 1.0f - lbExpNeg(om.tau[0] * rho[l]);
      p[1][l] = 1.0f - lbExpNeg(om.tau[1] * rho[l]);
    } else {
      p[0][l] = rho[l];
      p[1][l] = rho[l];
    }
  }
}

struct Dims {
  int nx = 0, ny = 0, nz = 0;
  CANOPY_HD int64_t count() const { return int64_t(nx) * ny * nz; }
  CANOPY_HD int64_t index(int x, int y, int z) const { return (int64_t(z) * ny + y) * nx + x; }
  CANOPY_HD bool interior(int x, int y, int z) const {
    return x > 0 && y > 0 && z > 0 && x < nx - 1 && y < ny - 1 && z < nz - 1;
  }
};

// The collision of L nodes of one kind known at compile time (Wood: all wood, else all leaf/empty),
// one per lane:   out_i = max(0, f_i + (Omega (p . f))_i),  f_0 zeroed first at leaf nodes, where
// p_m is the node's interaction probability for direction m (OmegaSet; the dissertation's
// rho (Omega f)_i when om.beerLambert == 0, up to the order of the roundings).
// f is modified (f_0 zeroing). (Omega f) is formed with grouped sums (omega_product.h, generated):
// Omega's entries take one value per class of directions in each row (omegaIsClassStructured),
// so each row multiplies sums of f over its classes: ~360 operations instead of the full
// product's 722. Every lane computes the same IEEE operations in the same order whatever L is:
// L = 1 on the GPU (one thread per node), L = 8 on the CPU (the compiler vectorises across lanes),
// so both backends produce the same bits (solve_cuda.cu is built without FMA contraction). When
// every lane has rho == 0 the product is skipped; that is bit-identical to the general path
// (f + 0 * x == f for finite x and f >= 0).
// The kind is a template parameter so that every Omega entry is read at a compile-time offset: on
// the GPU the matrix is a kernel parameter (constant memory) and a run-time kind would turn its
// uniform operands into per-thread indexed constant loads (measured: docs/performance.md, 'Omega at compile-time offsets').
// Fused = true uses fmaf in the product (one rounding per term instead of two): only the standalone
// measurement bench/lbsolve/collide_fma_cpu.cpp uses it; every solver uses Fused = false.
template <int L, bool Wood, bool Fused = false>
CANOPY_HD CANOPY_FORCEINLINE void collideKind(const OmegaSet& om, const float rho[L], float f[kQ][L],
                                              float out[kQ][L]) {
  if (!Wood) {
    for (int l = 0; l < L; ++l) f[0][l] = 0.f;  // absorbed light leaves the visible spectrum
  }
  bool empty = true;
  for (int l = 0; l < L; ++l) empty = empty && rho[l] == 0.f;
  if (empty) {
    CANOPY_UNROLL
    for (int i = 0; i < kQ; ++i)
      for (int l = 0; l < L; ++l) out[i][l] = f[i][l];
    return;
  }
  // What interacts: g_m = p_m f_m (p by direction class), then out = f + Omega g.
  float p[2][L], g[kQ][L], acc[kQ][L];
  interactionProbabilities<L>(om, rho, p);
  CANOPY_UNROLL
  for (int m = 0; m < kQ; ++m)
    for (int l = 0; l < L; ++l) g[m][l] = p[lattice::isAxial(m) || m == 0 ? 0 : 1][l] * f[m][l];
  omegaProduct<L, Wood, Fused>(om.col[Wood ? 1 : 0], g, acc);
  CANOPY_UNROLL
  for (int i = 0; i < kQ; ++i) {
    for (int l = 0; l < L; ++l) {
      const float v = f[i][l] + acc[i][l];
      out[i][l] = v > 0.f ? v : 0.f;
    }
  }
}

// The same with the kind known at run time (all L lanes wood, or none).
template <int L>
CANOPY_HD CANOPY_FORCEINLINE void collideLanes(const OmegaSet& om, bool wood, const float rho[L],
                                               float f[kQ][L], float out[kQ][L]) {
  if (wood) {
    collideKind<L, true>(om, rho, f, out);
  } else {
    collideKind<L, false>(om, rho, f, out);
  }
}

// Kind of the nodes an update is instantiated for: known at compile time (leaf/empty, or wood), or
// read from the coded density at run time.
enum NodeKind : int { kAnyKind = -1, kLeafKind = 0, kWoodKind = 1 };

// One node's collision; `coded` is rho (leaf/empty) or -rho (wood). With Kind != kAnyKind the
// caller guarantees the node is of that kind.
template <int Kind = kAnyKind>
CANOPY_HD CANOPY_FORCEINLINE void collide(const OmegaSet& om, float coded, float f[kQ], float out[kQ]) {
  const bool wood = Kind == kAnyKind ? coded < 0.f : Kind == kWoodKind;
  const float rho[1] = {wood ? -coded : coded};
  float fl[kQ][1], ol[kQ][1];
  CANOPY_UNROLL
  for (int m = 0; m < kQ; ++m) fl[m][0] = f[m];
  if constexpr (Kind == kAnyKind) {
    collideLanes<1>(om, wood, rho, fl, ol);
  } else {
    collideKind<1, Kind == kWoodKind>(om, rho, fl, ol);
  }
  CANOPY_UNROLL
  for (int m = 0; m < kQ; ++m) f[m] = fl[m][0], out[m] = ol[m][0];
}

// The push update of L consecutive nodes (x .. x+L-1, y, z) of the same kind (listing 5.2): load
// their 19 arriving values from `in`, collide, and write value m to the neighbour r + c_m in `out`
// if that neighbour is interior. Every node, boundary included, is a source; only interior nodes
// are targets, and each (target, m) pair has exactly one source, so the update is race-free with
// separate in/out buffers (ping-pong). Precondition: all L nodes are wood, or none is (and, with
// Kind != kAnyKind, they are of that kind).
template <int L, int Kind = kAnyKind>
CANOPY_HD CANOPY_FORCEINLINE void updateLanes(const OmegaSet& om, const Dims& d, const float* coded,
                                              const float* in, float* out, int x, int y, int z) {
  const int64_t n = d.count();
  const int64_t idx = d.index(x, y, z);
  float f[kQ][L], post[kQ][L], rho[L];
  const bool wood = Kind == kAnyKind ? coded[idx] < 0.f : Kind == kWoodKind;
  for (int l = 0; l < L; ++l) rho[l] = wood ? -coded[idx + l] : coded[idx + l];
  CANOPY_UNROLL
  for (int m = 0; m < kQ; ++m)
    for (int l = 0; l < L; ++l) f[m][l] = in[m * n + idx + l];
  if constexpr (Kind == kAnyKind) {
    collideLanes<L>(om, wood, rho, f, post);
  } else {
    collideKind<L, Kind == kWoodKind>(om, rho, f, post);
  }
  CANOPY_UNROLL
  for (int m = 0; m < kQ; ++m) {
    const int ty = y + lattice::dir(m, 1), tz = z + lattice::dir(m, 2);
    if (ty < 1 || tz < 1 || ty > d.ny - 2 || tz > d.nz - 2) continue;
    const int dx = lattice::dir(m, 0);
    const int64_t target = d.index(x + dx, ty, tz);
    for (int l = 0; l < L; ++l) {
      const int tx = x + l + dx;
      if (tx >= 1 && tx <= d.nx - 2) out[m * n + target + l] = post[m][l];
    }
  }
}

template <int Kind = kAnyKind>
CANOPY_HD CANOPY_FORCEINLINE void updateNode(const OmegaSet& om, const Dims& d, const float* coded,
                                             const float* in, float* out, int x, int y, int z) {
  updateLanes<1, Kind>(om, d, coded, in, out, x, y, z);
}

// Initial state of node idx for a solve: boundary nodes hold the fixed boundary values, interior
// nodes start at 0 (§5.1 / listing 5.1).
CANOPY_HD CANOPY_FORCEINLINE void initNode(const Dims& d, const float boundary[kQ], float* state,
                                           int x, int y, int z) {
  const int64_t n = d.count(), idx = d.index(x, y, z);
  const bool in = d.interior(x, y, z);
  CANOPY_UNROLL
  for (int m = 0; m < kQ; ++m) state[m * n + idx] = in ? 0.f : boundary[m];
}

// Total site density rho = sum_{m=0..18} f_m (§2.2): the value stored per node and channel.
CANOPY_HD CANOPY_FORCEINLINE float nodeTotal(const float* state, int64_t n, int64_t idx) {
  float s = 0.f;
  CANOPY_UNROLL
  for (int m = 0; m < kQ; ++m) s += state[m * n + idx];
  return s;
}

// The total of a boundary node: nodeTotal of a node holding the boundary values (same bits).
CANOPY_HD CANOPY_FORCEINLINE float boundaryTotal(const float boundary[kQ]) {
  float t = 0.f;
  CANOPY_UNROLL
  for (int m = 0; m < kQ; ++m) t += boundary[m];
  return t;
}

// ---- Building Omega (host) ----------------------------------------------------------------

// The normalised Henyey-Greenstein phase pn_ij(g) (eq. 4.1-4.2) for output direction i and input
// direction j (both 1..18), in double precision. The factor (1 - g^2) of p_ij cancels in the
// normalisation and is dropped, so |g| < 1 never divides 0 by 0; |g| = 1 takes the limit: all
// weight on i = j (g = 1) or i = opposite(j) (g = -1), pn = 24 / (2 or 1).
// Precondition: -1 <= g <= 1.
double normalisedPhase(double g, int i, int j);

// Omega (eq. 2.15-2.17) for absorption sigmaA, scattering sigmaS (sigma_t = sigmaA + sigmaS) and
// anisotropy g, written column-major into col[j][i].
void buildOmega(double sigmaA, double sigmaS, double g, float col[kQ][kQ]);

// The leaf (g) and wood (gWood; the parameters' default is -1) matrices of one channel, with the Beer-Lambert
// interaction of extinction `sigma` per lattice cell at density 1 (sigma > 0), or the
// dissertation's linear one (sigma == 0; OmegaSet).
OmegaSet makeOmegaSet(double sigmaA, double sigmaS, double g, double gWood, double sigma);

// True when in every row i of col (col[j][i] = Omega_ij) the entries of each class of directions
// j >= 1 (c_j axial or diagonal, and c_i . c_j) are bitwise equal: what omegaProduct assumes.
// buildOmega's matrices are (tested); Solver::solve refuses any other.
bool omegaIsClassStructured(const float col[kQ][kQ]);

}  // namespace canopy::lb
