// solve_cpu.cpp: the CPU (TBB) backend, the reference every test runs. It applies the CANOPY_HD
// functions of collide.h, the same ones the CUDA kernels call, over rows of the lattice.
#include <algorithm>
#include <cmath>
#include <utility>

#include <tbb/blocked_range.h>
#include <tbb/parallel_reduce.h>

#include "canopy/errors.h"
#include "canopy/parallel.h"
#include "pull_stream.h"
#include "solver.h"

namespace canopy::lb {
namespace {

constexpr int kLanes = 8;

class CpuSolver final : public Solver {
 public:
  explicit CpuSolver(const DenseLattice& l)
      : lat_(l), cur_(size_t(kQ) * l.dims.count()), prev_(size_t(kQ) * l.dims.count()) {}
  std::string name() const override { return "cpu"; }

 protected:
  void init(const float boundary[kQ]) override {
    const Dims d = lat_.dims;
    forRows([&](int y, int z) {
      for (int x = 0; x < d.nx; ++x) {
        initNode(d, boundary, cur_.data(), x, y, z);
        initNode(d, boundary, prev_.data(), x, y, z);
      }
    });
  }

  void step(const OmegaSet& omega) override {
    const Dims d = lat_.dims;
    const float* coded = lat_.coded.data();
    const float* in = cur_.data();
    float* out = prev_.data();  // interior fully rewritten; boundary already holds its values
    forRows([&](int y, int z) {
      // Runs of 8 nodes of one kind go through the 8-lane update (vectorised across x); the rest,
      // node by node. Both compute the same bits per node (collide.h).
      const float* rowCoded = coded + d.index(0, y, z);
      int x = 0;
      for (; x + kLanes <= d.nx; x += kLanes) {
        bool uniform = true;
        for (int l = 1; l < kLanes; ++l) uniform = uniform && ((rowCoded[x + l] < 0.f) == (rowCoded[x] < 0.f));
        if (uniform) {
          updateLanes<kLanes>(omega, d, coded, in, out, x, y, z);
        } else {
          for (int l = 0; l < kLanes; ++l) updateNode(omega, d, coded, in, out, x + l, y, z);
        }
      }
      for (; x < d.nx; ++x) updateNode(omega, d, coded, in, out, x, y, z);
    });
    std::swap(cur_, prev_);
  }

  float residual() override {
    const int64_t n = lat_.dims.count();
    using Pair = std::pair<float, float>;  // (max |delta rho|, max rho)
    const Pair r = tbb::parallel_reduce(
        tbb::blocked_range<int64_t>(0, n, 4096), Pair(0.f, 0.f),
        [&](const tbb::blocked_range<int64_t>& range, Pair acc) {
          for (int64_t i = range.begin(); i != range.end(); ++i) {
            const float a = nodeTotal(cur_.data(), n, i), b = nodeTotal(prev_.data(), n, i);
            acc.first = std::max(acc.first, std::abs(a - b));
            acc.second = std::max(acc.second, a);
          }
          return acc;
        },
        [](Pair a, Pair b) { return Pair(std::max(a.first, b.first), std::max(a.second, b.second)); });
    return r.second > 0.f ? r.first / r.second : 0.f;
  }

  std::vector<float> gather() override {
    std::vector<float> v(lat_.stored.size());
    const int64_t n = lat_.dims.count();
    parallelFor(int64_t(v.size()), [&](int64_t k) { v[k] = nodeTotal(cur_.data(), n, lat_.stored[k]); });
    return v;
  }

 private:
  template <class F>
  void forRows(F&& f) {
    const Dims d = lat_.dims;
    parallelFor(int64_t(d.ny) * d.nz, [&](int64_t row) { f(int(row % d.ny), int(row / d.ny)); }, 4);
  }

  const DenseLattice& lat_;
  std::vector<float> cur_, prev_;
};

}  // namespace

std::unique_ptr<Solver> makeCpuSolver(const DenseLattice& lattice) {
  return std::make_unique<CpuSolver>(lattice);
}

int64_t cudaSolverBytes(const DenseLattice& l, CudaScheme scheme) {
  const Dims d = l.dims;
  const int64_t n = d.count(), k = int64_t(l.stored.size());
  const int64_t stored = k * int64_t(sizeof(int64_t) + sizeof(float));
  int64_t wood = 0, occupied = 0;
  for (int64_t i = 0; i < n; ++i) {
    wood += l.coded[size_t(i)] < 0.f;
    occupied += l.coded[size_t(i)] != 0.f;
  }
  if (scheme == CudaScheme::Push)
    return n * (2 * kQ + 1) * int64_t(sizeof(float)) + wood * int64_t(sizeof(int64_t)) + stored;
  if (scheme == CudaScheme::Pull)
    return 2 * pullStateFloats(pullLayout(d)) * int64_t(sizeof(float)) + 2 * n * int64_t(sizeof(float)) + stored;
  const int64_t boundary = n - int64_t(std::max(d.nx - 2, 0)) * std::max(d.ny - 2, 0) * std::max(d.nz - 2, 0);
  return n * (kQ + 2) * int64_t(sizeof(float)) + occupied * int64_t(sizeof(int64_t) + sizeof(float)) +
         boundary * int64_t(sizeof(int64_t)) + stored;
}

#ifndef CANOPY_HAS_CUDA
std::unique_ptr<Solver> makeCudaSolver(const DenseLattice&, int, CudaScheme) {
  throw unsupported("--device cuda: this build of Canopy has no CUDA backend");
}
int64_t cudaFreeBytes(int) { return 0; }
#endif

}  // namespace canopy::lb
