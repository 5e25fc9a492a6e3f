// solve_cuda.cu: the CUDA backend. The kernels call the CANOPY_HD functions of collide.h, the
// same ones the CPU reference runs (solve_cpu.cpp).
//
// Layout and memory (PIPELINE.md §2, issue 3):
// - Structure of arrays: state[m * n + idx], idx = (z*ny + y)*nx + x. One thread per node, x
//   fastest within a block, so for every m a warp reads 32 consecutive floats (coalesced); the
//   pushed writes to r + c_m are shifted by at most one element in x (two 32-byte sectors).
// - The 19 values of a node live in registers (fully unrolled loops, as listing 5.2 replaces the
//   local array `in` by 19 scalars); Omega (leaf and wood, 2 x 19 x 19 floats) is a kernel
//   parameter, i.e. in constant memory, read with uniform addresses.
// - Ping-pong (not in place): two state buffers of 19 floats per node plus 4 bytes of coded
//   density: 156 bytes per node, 2.62 GB for a 256^3 lattice (0.33 GB for 128^3).
// - Built with --fmad=false (CMakeLists.txt): no multiply-add contraction, so each node computes
//   exactly the same IEEE operations in the same order as the CPU reference and the results agree
//   bit for bit (the CUDA test allows 1e-5 relative as the issue states).
#include <cstdio>
#include <cstring>

#include "canopy/parallel_cuda.cuh"
#include "solver.h"

namespace canopy::lb {
namespace {

constexpr int kBlockX = 128;

__global__ void __launch_bounds__(kBlockX) stepKernel(const OmegaSet omega, const Dims d,
                                                      const float* __restrict__ coded,
                                                      const float* __restrict__ in,
                                                      float* __restrict__ out) {
  const int x = int(blockIdx.x) * kBlockX + int(threadIdx.x);
  if (x >= d.nx) return;
  updateNode(omega, d, coded, in, out, x, int(blockIdx.y), int(blockIdx.z));
}

struct Boundary {
  float f[kQ];
};

__global__ void initKernel(const Boundary b, const Dims d, float* __restrict__ a, float* __restrict__ c) {
  const int x = int(blockIdx.x) * kBlockX + int(threadIdx.x);
  if (x >= d.nx) return;
  initNode(d, b.f, a, x, int(blockIdx.y), int(blockIdx.z));
  initNode(d, b.f, c, x, int(blockIdx.y), int(blockIdx.z));
}

// max |rho_cur - rho_prev| and max rho_cur over all nodes. Non-negative floats order like their
// bit patterns, so atomicMax on unsigned ints reduces them exactly (and deterministically).
__global__ void residualKernel(const float* __restrict__ cur, const float* __restrict__ prev,
                               int64_t n, unsigned* __restrict__ result) {
  float dmax = 0.f, rmax = 0.f;
  for (int64_t i = blockIdx.x * int64_t(blockDim.x) + threadIdx.x; i < n;
       i += int64_t(gridDim.x) * blockDim.x) {
    const float a = nodeTotal(cur, n, i), b = nodeTotal(prev, n, i);
    dmax = fmaxf(dmax, fabsf(a - b));
    rmax = fmaxf(rmax, a);
  }
  for (int o = 16; o > 0; o >>= 1) {
    dmax = fmaxf(dmax, __shfl_down_sync(0xffffffffu, dmax, o));
    rmax = fmaxf(rmax, __shfl_down_sync(0xffffffffu, rmax, o));
  }
  if ((threadIdx.x & 31) == 0) {
    atomicMax(&result[0], __float_as_uint(dmax));
    atomicMax(&result[1], __float_as_uint(rmax));
  }
}

__global__ void gatherKernel(const float* __restrict__ cur, int64_t n, const int64_t* __restrict__ stored,
                             int64_t k, float* __restrict__ values) {
  for (int64_t i = blockIdx.x * int64_t(blockDim.x) + threadIdx.x; i < k;
       i += int64_t(gridDim.x) * blockDim.x)
    values[i] = nodeTotal(cur, n, stored[i]);
}

class CudaSolver final : public Solver {
 public:
  CudaSolver(const DenseLattice& l, int gpu) : lat_(l), gpu_(gpu) {
    CANOPY_CUDA_CHECK(cudaSetDevice(gpu));
    size_t freeBytes = 0, totalBytes = 0;
    CANOPY_CUDA_CHECK(cudaMemGetInfo(&freeBytes, &totalBytes));
    const int64_t need = cudaSolverBytes(l);
    if (need > int64_t(freeBytes))
      throw runtimeError("GPU " + std::to_string(gpu) + " has " + std::to_string(freeBytes >> 20) +
                         " MiB free, the lattice needs " + std::to_string(need >> 20) + " MiB");
    const int64_t n = l.dims.count();
    bufA_.resize(size_t(kQ) * n);
    bufB_.resize(size_t(kQ) * n);
    cur_ = bufA_.data();
    prev_ = bufB_.data();
    coded_.resize(size_t(n));
    coded_.upload(l.coded.data(), l.coded.size());
    stored_.resize(l.stored.size());
    if (!l.stored.empty()) stored_.upload(l.stored.data(), l.stored.size());
    values_.resize(l.stored.size());
    result_.resize(2);
    CANOPY_CUDA_CHECK(cudaStreamCreate(&stream_));
  }
  ~CudaSolver() override { cudaStreamDestroy(stream_); }
  std::string name() const override { return "cuda:" + std::to_string(gpu_); }

 protected:
  dim3 grid() const {
    const Dims d = lat_.dims;
    return dim3(unsigned((d.nx + kBlockX - 1) / kBlockX), unsigned(d.ny), unsigned(d.nz));
  }
  void init(const float boundary[kQ]) override {
    CANOPY_CUDA_CHECK(cudaSetDevice(gpu_));
    Boundary b;
    std::memcpy(b.f, boundary, sizeof b.f);
    initKernel<<<grid(), kBlockX, 0, stream_>>>(b, lat_.dims, cur_, prev_);
    CANOPY_CUDA_CHECK(cudaGetLastError());
  }
  void step(const OmegaSet& omega) override {
    stepKernel<<<grid(), kBlockX, 0, stream_>>>(omega, lat_.dims, coded_.data(), cur_, prev_);
    CANOPY_CUDA_CHECK(cudaGetLastError());
    std::swap(cur_, prev_);
  }
  float residual() override {
    CANOPY_CUDA_CHECK(cudaMemsetAsync(result_.data(), 0, 2 * sizeof(unsigned), stream_));
    residualKernel<<<1024, 256, 0, stream_>>>(cur_, prev_, lat_.dims.count(), result_.data());
    CANOPY_CUDA_CHECK(cudaGetLastError());
    unsigned bits[2];
    CANOPY_CUDA_CHECK(cudaMemcpyAsync(bits, result_.data(), sizeof bits, cudaMemcpyDeviceToHost, stream_));
    CANOPY_CUDA_CHECK(cudaStreamSynchronize(stream_));
    float v[2];
    std::memcpy(v, bits, sizeof v);
    return v[1] > 0.f ? v[0] / v[1] : 0.f;
  }
  std::vector<float> gather() override {
    const int64_t k = int64_t(lat_.stored.size());
    std::vector<float> out(size_t(k), 0.f);
    if (k > 0) {
      gatherKernel<<<1024, 256, 0, stream_>>>(cur_, lat_.dims.count(), stored_.data(), k, values_.data());
      CANOPY_CUDA_CHECK(cudaGetLastError());
      CANOPY_CUDA_CHECK(cudaMemcpyAsync(out.data(), values_.data(), size_t(k) * sizeof(float),
                                        cudaMemcpyDeviceToHost, stream_));
    }
    CANOPY_CUDA_CHECK(cudaStreamSynchronize(stream_));
    return out;
  }

 private:
  const DenseLattice& lat_;
  int gpu_;
  cudaStream_t stream_ = nullptr;
  cuda::DeviceBuffer<float> bufA_, bufB_, coded_, values_;
  float* cur_ = nullptr;   // the current state (one of bufA_/bufB_)
  float* prev_ = nullptr;  // the previous state; the next step writes here
  cuda::DeviceBuffer<int64_t> stored_;
  cuda::DeviceBuffer<unsigned> result_;
};

}  // namespace

std::unique_ptr<Solver> makeCudaSolver(const DenseLattice& lattice, int gpu) {
  return std::make_unique<CudaSolver>(lattice, gpu);
}

}  // namespace canopy::lb
