// beam.cpp: directBeam() (beam.h).
#include "beam.h"

#include <algorithm>

#include "canopy/errors.h"
#include "canopy/parallel.h"

namespace canopy::lb {

namespace {

// The beam's direction on the lattice and the slices it is walked in.
struct BeamWalk {
  Dims d;
  int n[3];
  int c[3];
  int a, u, v;  // the axis the slices are taken across, and the slice's two axes
  // Steps back to the boundary along -c from interior node r: the iteration at which the beam first
  // arrives there.
  int depthOf(const int r[3]) const {
    int depth = 1 << 30;
    for (int b = 0; b < 3; ++b)
      if (c[b] != 0) depth = std::min(depth, c[b] > 0 ? r[b] : n[b] - 1 - r[b]);
    return depth;
  }
};

// The walk of base `base` on lattice dims d.
BeamWalk beamWalk(const Dims& d, int base) {
  BeamWalk w{d, {d.nx, d.ny, d.nz}, {lattice::dir(base, 0), lattice::dir(base, 1), lattice::dir(base, 2)}, 0, 0, 0};
  // The slices are taken across an axis the beam moves along, and walked downstream: every node's
  // upstream neighbour r - c lies in the slice before.
  w.a = w.c[2] != 0 ? 2 : w.c[1] != 0 ? 1 : 0;
  w.u = w.a == 0 ? 1 : 0, w.v = w.a == 2 ? 1 : 2;
  return w;
}

// f_j of the beam at every node after `iterations` iterations, slice by slice downstream.
std::vector<float> marchBeam(const DenseLattice& lattice, const OmegaSet& omega, const BeamWalk& w, int cls,
                             int iterations, float boundary) {
  const Dims& d = w.d;
  const int* n = w.n;
  const int* c = w.c;
  const int a = w.a, u = w.u, v = w.v;
  // An interaction removes sigma_t of what interacts from direction j (Omega_jj = -sigma_t + what
  // is scattered back into j itself, which is scattered light, not beam); the class of c_j picks p.
  const float negSigmaT = -omega.sigmaT;
  std::vector<float> beam(size_t(d.count()), 0.0f);
  const int64_t off = d.index(c[0], c[1], c[2]) - d.index(0, 0, 0);
  for (int s = 0; s < n[a]; ++s) {
    const int k = c[a] > 0 ? s : n[a] - 1 - s;
    parallelFor(int64_t(n[u]) * n[v], [&](int64_t q) {
      int r[3];
      r[a] = k;
      r[u] = int(q % n[u]);
      r[v] = int(q / n[u]);
      const int64_t idx = d.index(r[0], r[1], r[2]);
      if (!d.interior(r[0], r[1], r[2])) {
        beam[size_t(idx)] = boundary;  // the outer layer keeps its fixed value
        return;
      }
      if (w.depthOf(r) > iterations) return;  // still 0
      // The upstream node keeps what does not interact there: f + (-sigma_t) p_j f.
      const float f = beam[size_t(idx - off)];
      const float coded = lattice.coded[size_t(idx - off)];
      const float rho[1] = {coded < 0.0f ? -coded : coded};
      float out = f;
      if (rho[0] != 0.0f) {
        float p[2][1];
        interactionProbabilities<1>(omega, rho, p);
        const float x = f + negSigmaT * (p[cls][0] * f);
        out = x > 0.0f ? x : 0.0f;
      }
      beam[size_t(idx)] = out;
    }, 256);
  }
  return beam;
}

// The total at the stored nodes: f_0 + f_j (nodeTotal adds f_0 first, then zeros up to f_j).
// f_0 is what the node absorbed of the beam at the iteration before the last (c_0 = 0 keeps it
// at the node), the collision's row 0 restricted to Omega_00 and Omega_0j.
std::vector<float> beamTotals(const DenseLattice& lattice, const OmegaSet& omega, const BeamWalk& w, int base, int cls,
                              int iterations, const std::vector<float>& beam) {
  const Dims& d = w.d;
  const float row0[2][2] = {{omega.col[0][0][0], omega.col[0][base][0]}, {omega.col[1][0][0], omega.col[1][base][0]}};
  std::vector<float> values(lattice.stored.size());
  parallelFor(int64_t(values.size()), [&](int64_t i) {
    const int64_t idx = lattice.stored[size_t(i)];
    const int64_t row = idx / d.nx;
    const int r[3] = {int(idx - row * d.nx), int(row % d.ny), int(row / d.ny)};
    const float fj = beam[size_t(idx)];
    float f0 = 0.0f;
    const float coded = lattice.coded[size_t(idx)];
    if (d.interior(r[0], r[1], r[2]) && coded != 0.0f) {
      const int depth = w.depthOf(r);
      const bool wood = coded < 0.0f;
      const float rho[1] = {wood ? -coded : coded};
      float p[2][1];
      interactionProbabilities<1>(omega, rho, p);
      const float* wr = row0[wood ? 1 : 0];
      // Iterations depth .. iterations-1 collided the beam fj here; a leaf node zeroes f_0 first at
      // each, so only the last one counts, a wood node carries f_0 over.
      const int first = wood ? depth : std::max(depth, iterations - 1);
      for (int t = first; t < iterations; ++t) {
        const float prev = wood ? f0 : 0.0f;
        float acc = 0.0f;
        acc += wr[0] * (p[0][0] * prev);
        acc += wr[1] * (p[cls][0] * fj);
        const float x = prev + acc;
        f0 = x > 0.0f ? x : 0.0f;
      }
    }
    float total = 0.0f;
    total += f0;
    total += fj;
    values[size_t(i)] = total;
  });
  return values;
}

}  // namespace

std::vector<float> directBeam(const DenseLattice& lattice, const OmegaSet& omega, int base, int iterations,
                              float boundary) {
  if (base < 1 || base >= kQ) throw runtimeError("internal: directBeam of base " + std::to_string(base));
  const BeamWalk w = beamWalk(lattice.dims, base);
  const int cls = lattice::isAxial(base) ? 0 : 1;
  const std::vector<float> beam = marchBeam(lattice, omega, w, cls, iterations, boundary);
  return beamTotals(lattice, omega, w, base, cls, iterations, beam);
}

}  // namespace canopy::lb
