// solve_cuda.cu: the CUDA backend. The kernels call the CANOPY_HD functions of collide.h and
// shift_stream.h, the same ones the CPU reference (solve_cpu.cpp) and the CPU tests run.
//
// Schemes (solver.h, CudaScheme; measurements in docs/performance.md and bench/RESULTS.md):
// - Shift (default): streaming by index shift (shift_stream.h). One state buffer of 19 floats per
//   node, updated in place; an iteration is one launch over the occupied interior nodes (leaf
//   nodes, then wood nodes, in separate blocks) and the empty boundary nodes (occupied boundary
//   nodes, if any, in a second launch). A checked iteration also keeps the occupied nodes' totals
//   before their collision; the residual is then one pass over the state. ShiftSplit: the same
//   iteration as three launches of leaner kernels (measured slower: the parts no longer overlap).
// - Pull: the push update reorganised (pull_stream.h): post-collision values stored aligned at each
//   node in tiles of 32 nodes (19 directions contiguous per tile), arrivals read from the
//   neighbours; ping-pong buffers, the same 156 bytes moved per node update, the same bits.
// - Push: the push update of listing 5.2 over every node: structure of arrays, state[m * n + idx],
//   idx = (z*ny + y)*nx + x, one thread per node, x fastest within a block (a warp reads 32
//   consecutive floats for every m; the pushed writes are shifted by at most one element in x),
//   ping-pong buffers (156 bytes per node). Leaf/empty nodes and wood nodes run in separate
//   launches (wood: a list of its nodes) so that each kernel's collision has its Omega at
//   compile-time offsets (collide.h, collideKind).
// In both the 19 values of a node live in registers (fully unrolled loops) and Omega (leaf and
// wood, 2 x 19 x 19 floats) is a kernel parameter, i.e. in constant memory, read with uniform
// addresses.
// Built with --fmad=false (CMakeLists.txt): no multiply-add contraction, so each node computes the
// same IEEE operations in the same order as the CPU reference and the results agree bit for bit
// (tests/lbsolve/test_lbsolve_cuda.cpp).
#include <algorithm>
#include <cstdio>
#include <cstring>

#include "canopy/errors.h"
#include "canopy/parallel_cuda.cuh"
#include "pull_stream.h"
#include "shift_stream.h"
#include "solver.h"

namespace canopy::lb {
namespace {

constexpr int kBlockX = 128;
constexpr int kReduceBlocks = 1024, kReduceThreads = 256;
constexpr int kRowBlocks = 2048, kRowThreads = 128;  // the shift scheme's full passes (forEachNode)

struct Boundary {
  float f[kQ];
};

// Node index -> (x, y, z).
__device__ __forceinline__ void coordsOf(const Dims& d, int64_t p, int& x, int& y, int& z) {
  const int64_t row = p / d.nx;
  x = int(p - row * d.nx);
  y = int(row % d.ny);
  z = int(row / d.ny);
}

// max |a - b| and max a over a block, then one atomicMax pair per block. Non-negative floats
// order like their bit patterns, so atomicMax on unsigned ints reduces them exactly (and
// deterministically).
__device__ __forceinline__ void reduceMax2(float dmax, float rmax, unsigned* result) {
  __shared__ float sd[kReduceThreads / 32], sr[kReduceThreads / 32];
  for (int o = 16; o > 0; o >>= 1) {
    dmax = fmaxf(dmax, __shfl_down_sync(0xffffffffu, dmax, o));
    rmax = fmaxf(rmax, __shfl_down_sync(0xffffffffu, rmax, o));
  }
  const int warp = int(threadIdx.x) / 32, lane = int(threadIdx.x) % 32;
  if (lane == 0) sd[warp] = dmax, sr[warp] = rmax;
  __syncthreads();
  if (threadIdx.x == 0) {
    for (int w = 1; w < int(blockDim.x) / 32; ++w) dmax = fmaxf(dmax, sd[w]), rmax = fmaxf(rmax, sr[w]);
    atomicMax(&result[0], __float_as_uint(dmax));
    atomicMax(&result[1], __float_as_uint(rmax));
  }
}

// ---- Push scheme -----------------------------------------------------------------------------

// Leaf and empty nodes (wood nodes: pushWoodKernel).
__global__ void __launch_bounds__(kBlockX) pushLeafKernel(const OmegaSet omega, const Dims d,
                                                          const float* __restrict__ coded,
                                                          const float* __restrict__ in,
                                                          float* __restrict__ out) {
  const int x = int(blockIdx.x) * kBlockX + int(threadIdx.x);
  if (x >= d.nx) return;
  const int y = int(blockIdx.y), z = int(blockIdx.z);
  if (coded[d.index(x, y, z)] < 0.f) return;  // a wood node: pushWoodKernel
  updateNode<kLeafKind>(omega, d, coded, in, out, x, y, z);
}

__global__ void __launch_bounds__(kBlockX) pushWoodKernel(const OmegaSet omega, const Dims d,
                                                          const float* __restrict__ coded,
                                                          const float* __restrict__ in,
                                                          float* __restrict__ out,
                                                          const int64_t* __restrict__ wood, int64_t count) {
  const int64_t i = int64_t(blockIdx.x) * kBlockX + threadIdx.x;
  if (i >= count) return;
  int x, y, z;
  coordsOf(d, wood[i], x, y, z);
  updateNode<kWoodKind>(omega, d, coded, in, out, x, y, z);
}

__global__ void pushInitKernel(const Boundary b, const Dims d, float* __restrict__ a, float* __restrict__ c) {
  const int x = int(blockIdx.x) * kBlockX + int(threadIdx.x);
  if (x >= d.nx) return;
  initNode(d, b.f, a, x, int(blockIdx.y), int(blockIdx.z));
  initNode(d, b.f, c, x, int(blockIdx.y), int(blockIdx.z));
}

__global__ void __launch_bounds__(kReduceThreads) pushResidualKernel(const float* __restrict__ cur,
                                                                     const float* __restrict__ prev, int64_t n,
                                                                     unsigned* __restrict__ result) {
  float dmax = 0.f, rmax = 0.f;
  for (int64_t i = blockIdx.x * int64_t(blockDim.x) + threadIdx.x; i < n; i += int64_t(gridDim.x) * blockDim.x) {
    const float a = nodeTotal(cur, n, i), b = nodeTotal(prev, n, i);
    dmax = fmaxf(dmax, fabsf(a - b));
    rmax = fmaxf(rmax, a);
  }
  reduceMax2(dmax, rmax, result);
}

__global__ void pushGatherKernel(const float* __restrict__ cur, int64_t n, const int64_t* __restrict__ stored,
                                 int64_t k, float* __restrict__ values) {
  for (int64_t i = blockIdx.x * int64_t(blockDim.x) + threadIdx.x; i < k; i += int64_t(gridDim.x) * blockDim.x)
    values[i] = nodeTotal(cur, n, stored[i]);
}

// ---- Pull scheme (pull_stream.h) -------------------------------------------------------------

// Every interior node (leaf, empty and wood); grid (ceil(nx / 128), ny, nz), so a
// warp covers one tile of 32 nodes: every load of a direction reads 128 contiguous bytes (shifted by
// at most one node, i.e. two tiles), every store writes 128 aligned bytes. The blocks run in z-major
// order, so a launch's resident blocks read and write a few neighbouring z-slices; blocks scattered
// over the lattice (to mix the plant's colliding warps with the air's streaming ones) were slower
// by 7-13 points of the copy bandwidth (docs/performance.md, 'Row order and solves in flight').
__global__ void __launch_bounds__(kBlockX) pullLeafKernel(const OmegaSet omega, const PullLayout L,
                                                          const float* __restrict__ coded,
                                                          const float* __restrict__ in, float* __restrict__ out) {
  // Launched with programmatic dependent launch (launchPull): the blocks may be resident before the
  // previous iteration's launch has finished; nothing is read or written before it has, and its
  // stores are visible after this wait.
#if defined(__CUDA_ARCH__) && __CUDA_ARCH__ >= 900
  cudaGridDependencySynchronize();
#endif
  const int x = int(blockIdx.x) * kBlockX + int(threadIdx.x);
  const int y = int(blockIdx.y), z = int(blockIdx.z);
  // A wood node (the trunk: a few warps) takes the other branch, on the values already loaded (a
  // second kernel per iteration used to update the wood nodes from a list, loading their arrivals
  // again, scattered: docs/performance.md, 'Wood nodes in the pull kernel'). The boundary and padding lanes of an
  // interior row store the values they hold, so that every store covers whole sectors ('Whole sectors').
  pullNode(omega, L, coded, in, out, x, y, z);
}

// The boundary nodes' post values (constant over a solve) into both buffers.
__global__ void pullBoundaryKernel(const OmegaSet omega, const Boundary b, const PullLayout L,
                                   const float* __restrict__ coded, float* __restrict__ a, float* __restrict__ c) {
  const int x = int(blockIdx.x) * kBlockX + int(threadIdx.x);
  const int y = int(blockIdx.y), z = int(blockIdx.z);
  if (x >= L.d.nx || L.d.interior(x, y, z)) return;
  const float k = coded[L.d.index(x, y, z)];
  pullBoundaryNode(omega, L, b.f, k, a, x, y, z);
  pullBoundaryNode(omega, L, b.f, k, c, x, y, z);
}

// Every node's arrival total from `state` (the post values of the iteration before). Before the
// first step both buffers hold zeros (reset), so every interior total is 0, the initial state's.
__global__ void pullTotalsKernel(const PullLayout L, const float* __restrict__ state, float fixedTotal,
                                 float* __restrict__ totals) {
  const int x = int(blockIdx.x) * kBlockX + int(threadIdx.x);
  const int y = int(blockIdx.y), z = int(blockIdx.z);
  if (x >= L.d.nx) return;
  totals[L.d.index(x, y, z)] = pullArrivalTotal(L, state, fixedTotal, x, y, z);
}

__global__ void __launch_bounds__(kReduceThreads) pullResidualKernel(const PullLayout L, const float* __restrict__ state,
                                                                     float fixedTotal, const float* __restrict__ before,
                                                                     unsigned* __restrict__ result) {
  float dmax = 0.f, rmax = 0.f;
  const int64_t n = L.d.count();
  for (int64_t i = blockIdx.x * int64_t(blockDim.x) + threadIdx.x; i < n; i += int64_t(gridDim.x) * blockDim.x) {
    int x, y, z;
    coordsOf(L.d, i, x, y, z);
    const float a = pullArrivalTotal(L, state, fixedTotal, x, y, z);
    dmax = fmaxf(dmax, fabsf(a - before[i]));
    rmax = fmaxf(rmax, a);
  }
  reduceMax2(dmax, rmax, result);
}

__global__ void pullGatherKernel(const PullLayout L, const float* __restrict__ state, float fixedTotal,
                                 const int64_t* __restrict__ stored, int64_t k, float* __restrict__ values) {
  for (int64_t i = blockIdx.x * int64_t(blockDim.x) + threadIdx.x; i < k; i += int64_t(gridDim.x) * blockDim.x) {
    int x, y, z;
    coordsOf(L.d, stored[i], x, y, z);
    values[i] = pullArrivalTotal(L, state, fixedTotal, x, y, z);
  }
}

// ---- Shift scheme ----------------------------------------------------------------------------

// Boundary nodes are listed by packed coordinates (21 bits each: no division in the kernels).
constexpr int kCoordBits = 21;
__host__ __device__ __forceinline__ uint64_t packCoords(int x, int y, int z) {
  return uint64_t(x) | uint64_t(y) << kCoordBits | uint64_t(z) << (2 * kCoordBits);
}
__device__ __forceinline__ void unpackCoords(uint64_t c, int& x, int& y, int& z) {
  constexpr uint64_t mask = (uint64_t(1) << kCoordBits) - 1;
  x = int(c & mask), y = int(c >> kCoordBits & mask), z = int(c >> (2 * kCoordBits));
}

// The node lists of one shift iteration, each in its own range of blocks (so that a block's
// threads take one path): occupied interior leaf nodes, occupied interior wood nodes (with their
// coded density), empty boundary nodes. Occupied boundary nodes (none in canopy-voxelize's
// lattices, which keep the outer layer empty) have their own kernel.
struct ShiftLists {
  const int64_t* leaf;
  const float* leafCoded;
  int64_t leafCount, leafBlocks;
  const int64_t* wood;
  const float* woodCoded;
  int64_t woodCount, woodBlocks;
  const uint64_t* edge;  // empty boundary nodes, packed coordinates
  int64_t edgeCount, edgeBlocks;
};

// One iteration. With `totals` (an iteration the residual checks), each occupied node also stores
// its total before the collision at totals[p] (shift_stream.h).
__global__ void __launch_bounds__(kBlockX) shiftStepKernel(const OmegaSet omega, const Boundary b,
                                                           const ShiftOffsets s, const Dims d, const ShiftLists L,
                                                           float* __restrict__ state, float* __restrict__ totals) {
  const int64_t n = d.count();
  int64_t block = blockIdx.x;
  if (block < L.leafBlocks) {
    const int64_t i = block * kBlockX + threadIdx.x;
    if (i >= L.leafCount) return;
    const int64_t p = L.leaf[i];
    shiftCollideNode<kLeafKind>(omega, s, n, L.leafCoded[i], p, state, totals ? totals + p : nullptr);
    return;
  }
  block -= L.leafBlocks;
  if (block < L.woodBlocks) {
    const int64_t i = block * kBlockX + threadIdx.x;
    if (i >= L.woodCount) return;
    const int64_t p = L.wood[i];
    shiftCollideNode<kWoodKind>(omega, s, n, L.woodCoded[i], p, state, totals ? totals + p : nullptr);
    return;
  }
  block -= L.woodBlocks;
  const int64_t i = block * kBlockX + threadIdx.x;
  if (i >= L.edgeCount) return;
  int x, y, z;
  unpackCoords(L.edge[i], x, y, z);
  shiftBoundaryNode<true>(omega, d, b.f, s, 0.f, x, y, z, state);
}

// The same iteration in three launches (CudaScheme::ShiftSplit): occupied nodes of one kind, and
// empty boundary nodes, each kernel with only its own path (fewer registers than the one above).
template <int Kind>
__global__ void __launch_bounds__(kBlockX) shiftCollideKernel(const OmegaSet omega, const ShiftOffsets s, int64_t n,
                                                              const int64_t* __restrict__ nodes,
                                                              const float* __restrict__ nodeCoded, int64_t count,
                                                              float* __restrict__ state, float* __restrict__ totals) {
  const int64_t i = int64_t(blockIdx.x) * kBlockX + threadIdx.x;
  if (i >= count) return;
  const int64_t p = nodes[i];
  shiftCollideNode<Kind>(omega, s, n, nodeCoded[i], p, state, totals ? totals + p : nullptr);
}

__global__ void __launch_bounds__(kBlockX) shiftEdgeKernel(const OmegaSet omega, const Boundary b, const ShiftOffsets s,
                                                           const Dims d, const uint64_t* __restrict__ edge,
                                                           int64_t count, float* __restrict__ state) {
  const int64_t i = int64_t(blockIdx.x) * kBlockX + threadIdx.x;
  if (i >= count) return;
  int x, y, z;
  unpackCoords(edge[i], x, y, z);
  shiftBoundaryNode<true>(omega, d, b.f, s, 0.f, x, y, z, state);
}

__global__ void __launch_bounds__(kBlockX) shiftOccupiedBoundaryKernel(const OmegaSet omega, const Boundary b,
                                                                       const ShiftOffsets s, const Dims d,
                                                                       const uint64_t* __restrict__ nodes,
                                                                       const float* __restrict__ nodeCoded,
                                                                       int64_t count, float* __restrict__ state) {
  const int64_t i = int64_t(blockIdx.x) * kBlockX + threadIdx.x;
  if (i >= count) return;
  int x, y, z;
  unpackCoords(nodes[i], x, y, z);
  shiftBoundaryNode<false>(omega, d, b.f, s, nodeCoded[i], x, y, z, state);
}

// The full passes (totals before a checked step, residual): blocks walk rows (y, z) of the
// lattice, threads walk x, so the interior test needs no per-node division. Boundary nodes have
// the fixed total.
template <class F>
__device__ __forceinline__ void forEachNode(const Dims& d, F&& f) {
  const int64_t rows = int64_t(d.ny) * d.nz;
  for (int64_t row = blockIdx.x; row < rows; row += gridDim.x) {
    const int y = int(row % d.ny), z = int(row / d.ny);
    const bool rowInterior = y > 0 && z > 0 && y < d.ny - 1 && z < d.nz - 1;
    for (int x = int(threadIdx.x); x < d.nx; x += int(blockDim.x))
      f(row * d.nx + x, rowInterior && x > 0 && x < d.nx - 1);
  }
}

// The residual after a checked iteration t, in one pass: a node's total at t (offsets `now`) and
// at t - 1 (offsets `before`; occupied nodes: the total the step kept in `kept`).
__global__ void __launch_bounds__(kReduceThreads) shiftResidualKernel(const ShiftOffsets now, const ShiftOffsets before,
                                                                      const Dims d, float fixedTotal,
                                                                      const float* __restrict__ state,
                                                                      const float* __restrict__ coded,
                                                                      const float* __restrict__ kept,
                                                                      unsigned* __restrict__ result) {
  const int64_t n = d.count();
  float dmax = 0.f, rmax = 0.f;
  forEachNode(d, [&](int64_t p, bool interior) {
    float a = fixedTotal, b = fixedTotal;
    if (interior) {
      a = shiftNodeTotal(state, n, now, p);
      b = coded[p] != 0.f ? kept[p] : shiftNodeTotal(state, n, before, p);
    }
    dmax = fmaxf(dmax, fabsf(a - b));
    rmax = fmaxf(rmax, a);
  });
  reduceMax2(dmax, rmax, result);
}

__global__ void shiftGatherKernel(const ShiftOffsets s, const Dims d, float fixedTotal,
                                  const float* __restrict__ state, const int64_t* __restrict__ stored, int64_t k,
                                  float* __restrict__ values) {
  for (int64_t i = blockIdx.x * int64_t(blockDim.x) + threadIdx.x; i < k; i += int64_t(gridDim.x) * blockDim.x) {
    const int64_t p = stored[i];
    int x, y, z;
    coordsOf(d, p, x, y, z);
    values[i] = d.interior(x, y, z) ? shiftNodeTotal(state, d.count(), s, p) : fixedTotal;
  }
}

// ---- The solver ------------------------------------------------------------------------------
}  // namespace

int64_t cudaFreeBytes(int gpu) {
  CANOPY_CUDA_CHECK(cudaSetDevice(gpu));
  size_t freeBytes = 0, totalBytes = 0;
  CANOPY_CUDA_CHECK(cudaMemGetInfo(&freeBytes, &totalBytes));
  return int64_t(freeBytes);
}

namespace {

template <class T>
void uploadVector(cuda::DeviceBuffer<T>& buffer, const std::vector<T>& v) {
  buffer.resize(v.size());
  if (!v.empty()) buffer.upload(v.data(), v.size());
}

int64_t blocksFor(int64_t count) { return (count + kBlockX - 1) / kBlockX; }

bool isShift(CudaScheme scheme) { return scheme == CudaScheme::Shift || scheme == CudaScheme::ShiftSplit; }
bool isPull(CudaScheme scheme) { return scheme == CudaScheme::Pull; }

class CudaSolver final : public Solver {
 public:
  CudaSolver(const DenseLattice& l, int gpu, CudaScheme scheme)
      : lat_(l), gpu_(gpu), scheme_(scheme), pull_(pullLayout(l.dims)) {
    const int64_t freeBytes = cudaFreeBytes(gpu);  // also makes `gpu` this thread's device
    const int64_t need = cudaSolverBytes(l, scheme);
    if (need > freeBytes)
      throw runtimeError("GPU " + std::to_string(gpu) + " has " + std::to_string(freeBytes >> 20) +
                         " MiB free, the lattice needs " + std::to_string(need >> 20) + " MiB");
    const Dims d = l.dims;
    const int64_t n = d.count();
    coded_.resize(size_t(n));
    coded_.upload(l.coded.data(), l.coded.size());
    uploadVector(stored_, l.stored);
    values_.resize(l.stored.size());
    result_.resize(2);
    if (isShift(scheme)) {
      state_.resize(size_t(kQ) * n);
      totals_.resize(size_t(n));
      std::vector<int64_t> leaf, wood;
      std::vector<float> leafCoded, woodCoded, boundaryCoded;
      std::vector<uint64_t> edge, boundary;
      if (std::max({d.nx, d.ny, d.nz}) >= (1 << kCoordBits) || n > kMaxShiftNodes)
        throw runtimeError("the lattice is too large for the CUDA shift scheme (at most 2^31 - 1 nodes)");
      for (int z = 0; z < d.nz; ++z)
        for (int y = 0; y < d.ny; ++y)
          for (int x = 0; x < d.nx; ++x) {
            const int64_t p = d.index(x, y, z);
            const float c = l.coded[size_t(p)];
            if (!d.interior(x, y, z)) {
              if (c == 0.f) {
                edge.push_back(packCoords(x, y, z));
              } else {
                boundary.push_back(packCoords(x, y, z)), boundaryCoded.push_back(c);
              }
            } else if (c < 0.f) {
              wood.push_back(p), woodCoded.push_back(c);
            } else if (c != 0.f) {
              leaf.push_back(p), leafCoded.push_back(c);
            }
          }
      uploadVector(leaf_, leaf);
      uploadVector(leafCoded_, leafCoded);
      uploadVector(wood_, wood);
      uploadVector(woodCoded_, woodCoded);
      uploadVector(edge_, edge);
      uploadVector(boundary_, boundary);
      uploadVector(boundaryCoded_, boundaryCoded);
      lists_ = ShiftLists{leaf_.data(), leafCoded_.data(), int64_t(leaf.size()), blocksFor(int64_t(leaf.size())),
                          wood_.data(), woodCoded_.data(), int64_t(wood.size()), blocksFor(int64_t(wood.size())),
                          edge_.data(), int64_t(edge.size()), blocksFor(int64_t(edge.size()))};
    } else {
      const size_t floats = isPull(scheme) ? size_t(pullStateFloats(pull_)) : size_t(kQ) * n;
      bufA_.resize(floats);
      bufB_.resize(floats);
      cur_ = bufA_.data();
      prev_ = bufB_.data();
      if (isPull(scheme)) totals_.resize(size_t(n));
      // Wood nodes, for push's second kernel: every one (boundary nodes are sources there). Pull's
      // one kernel updates them with the others.
      std::vector<int64_t> wood;
      if (!isPull(scheme))
        for (int z = 0; z < d.nz; ++z)
          for (int y = 0; y < d.ny; ++y)
            for (int x = 0; x < d.nx; ++x) {
              const int64_t p = d.index(x, y, z);
              if (l.coded[size_t(p)] < 0.f) wood.push_back(p);
            }
      uploadVector(wood_, wood);
    }
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
    std::memcpy(boundary_values_.f, boundary, sizeof boundary_values_.f);
    fixedTotal_ = boundaryTotal(boundary);
    t_ = 0;
    if (isShift(scheme_)) {
      // Interior nodes start at 0; boundary slots are never read (shift_stream.h).
      CANOPY_CUDA_CHECK(cudaMemsetAsync(state_.data(), 0, state_.size() * sizeof(float), stream_));
    } else if (isPull(scheme_)) {
      // Interior post values start at 0; the boundary's are written by the first step, which has
      // Omega (pull_stream.h).
      CANOPY_CUDA_CHECK(cudaMemsetAsync(bufA_.data(), 0, bufA_.size() * sizeof(float), stream_));
      CANOPY_CUDA_CHECK(cudaMemsetAsync(bufB_.data(), 0, bufB_.size() * sizeof(float), stream_));
    } else {
      pushInitKernel<<<grid(), kBlockX, 0, stream_>>>(boundary_values_, lat_.dims, cur_, prev_);
      CANOPY_CUDA_CHECK(cudaGetLastError());
    }
  }

  void beforeCheckedStep() override {
    keepTotals_ = isShift(scheme_);
    // Pull: the totals of the current state, from the post values before it (before the first step:
    // zeros, the boundary's post values not written yet, so 0 inside, the initial state's).
    if (isPull(scheme_)) {
      pullTotalsKernel<<<grid(), kBlockX, 0, stream_>>>(pull_, prev_, fixedTotal_, totals_.data());
      CANOPY_CUDA_CHECK(cudaGetLastError());
    }
  }

  void step(const OmegaSet& omega) override {
    const Dims d = lat_.dims;
    if (isShift(scheme_)) {
      const ShiftOffsets offsets = shiftOffsets(d, t_);
      float* totals = keepTotals_ ? totals_.data() : nullptr;
      const ShiftLists& L = lists_;
      if (scheme_ == CudaScheme::ShiftSplit) {
        if (L.leafCount > 0)
          shiftCollideKernel<kLeafKind><<<unsigned(L.leafBlocks), kBlockX, 0, stream_>>>(
              omega, offsets, d.count(), L.leaf, L.leafCoded, L.leafCount, state_.data(), totals);
        if (L.woodCount > 0)
          shiftCollideKernel<kWoodKind><<<unsigned(L.woodBlocks), kBlockX, 0, stream_>>>(
              omega, offsets, d.count(), L.wood, L.woodCoded, L.woodCount, state_.data(), totals);
        if (L.edgeCount > 0)
          shiftEdgeKernel<<<unsigned(L.edgeBlocks), kBlockX, 0, stream_>>>(omega, boundary_values_, offsets, d, L.edge,
                                                                           L.edgeCount, state_.data());
        CANOPY_CUDA_CHECK(cudaGetLastError());
      } else if (const int64_t blocks = L.leafBlocks + L.woodBlocks + L.edgeBlocks; blocks > 0) {
        shiftStepKernel<<<unsigned(blocks), kBlockX, 0, stream_>>>(omega, boundary_values_, offsets, d, L,
                                                                   state_.data(), totals);
        CANOPY_CUDA_CHECK(cudaGetLastError());
      }
      totalsAt_ = keepTotals_ ? t_ : -1;
      keepTotals_ = false;
      const int64_t occupiedBoundary = int64_t(boundary_.size());
      if (occupiedBoundary > 0) {
        shiftOccupiedBoundaryKernel<<<unsigned(blocksFor(occupiedBoundary)), kBlockX, 0, stream_>>>(
            omega, boundary_values_, offsets, d, boundary_.data(), boundaryCoded_.data(), occupiedBoundary,
            state_.data());
        CANOPY_CUDA_CHECK(cudaGetLastError());
      }
    } else if (isPull(scheme_)) {
      if (t_ == 0) {
        pullBoundaryKernel<<<grid(), kBlockX, 0, stream_>>>(omega, boundary_values_, pull_, coded_.data(), cur_, prev_);
        CANOPY_CUDA_CHECK(cudaGetLastError());
      }
      launchPull(omega);
      std::swap(cur_, prev_);
    } else {
      pushLeafKernel<<<grid(), kBlockX, 0, stream_>>>(omega, d, coded_.data(), cur_, prev_);
      CANOPY_CUDA_CHECK(cudaGetLastError());
      const int64_t woodCount = int64_t(wood_.size());
      if (woodCount > 0) {
        pushWoodKernel<<<unsigned(blocksFor(woodCount)), kBlockX, 0, stream_>>>(omega, d, coded_.data(), cur_, prev_,
                                                                                wood_.data(), woodCount);
        CANOPY_CUDA_CHECK(cudaGetLastError());
      }
      std::swap(cur_, prev_);
    }
    ++t_;
  }

  // One pull iteration, cur_ -> prev_, as a programmatic dependent launch: the launch (block
  // scheduling) overlaps the end of the launch before it, whose results the kernel waits for first
  // (cudaGridDependencySynchronize). Between two pull launches of a solve this removes most of the
  // few microseconds a dependent launch otherwise waits (docs/performance.md, 'Programmatic dependent launch').
  void launchPull(const OmegaSet& omega) {
    cudaLaunchConfig_t config = {};
    config.gridDim = grid();
    config.blockDim = dim3(kBlockX);
    config.stream = stream_;
    cudaLaunchAttribute attribute[1];
    attribute[0].id = cudaLaunchAttributeProgrammaticStreamSerialization;
    attribute[0].val.programmaticStreamSerializationAllowed = 1;
    config.attrs = attribute;
    config.numAttrs = 1;
    const float* in = cur_;
    float* out = prev_;
    const float* coded = coded_.data();
    CANOPY_CUDA_CHECK(cudaLaunchKernelEx(&config, pullLeafKernel, omega, pull_, coded, in, out));
  }

  float residual() override {
    CANOPY_CUDA_CHECK(cudaMemsetAsync(result_.data(), 0, 2 * sizeof(unsigned), stream_));
    if (isShift(scheme_)) {
      if (t_ < 1 || totalsAt_ != t_ - 1) throw runtimeError("internal: shift residual without the kept totals");
      shiftResidualKernel<<<kRowBlocks, kRowThreads, 0, stream_>>>(
          shiftOffsets(lat_.dims, t_), shiftOffsets(lat_.dims, t_ - 1), lat_.dims, fixedTotal_, state_.data(),
          coded_.data(), totals_.data(), result_.data());
    } else if (isPull(scheme_)) {
      pullResidualKernel<<<kReduceBlocks, kReduceThreads, 0, stream_>>>(pull_, prev_, fixedTotal_, totals_.data(),
                                                                       result_.data());
    } else {
      pushResidualKernel<<<kReduceBlocks, kReduceThreads, 0, stream_>>>(cur_, prev_, lat_.dims.count(),
                                                                       result_.data());
    }
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
      if (isShift(scheme_)) {
        shiftGatherKernel<<<kReduceBlocks, kReduceThreads, 0, stream_>>>(
            shiftOffsets(lat_.dims, t_), lat_.dims, fixedTotal_, state_.data(), stored_.data(), k, values_.data());
      } else if (isPull(scheme_)) {
        pullGatherKernel<<<kReduceBlocks, kReduceThreads, 0, stream_>>>(pull_, prev_, fixedTotal_, stored_.data(), k,
                                                                       values_.data());
      } else {
        pushGatherKernel<<<kReduceBlocks, kReduceThreads, 0, stream_>>>(cur_, lat_.dims.count(), stored_.data(), k,
                                                                       values_.data());
      }
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
  CudaScheme scheme_;
  PullLayout pull_;  // pull: the tiled layout of bufA_/bufB_
  cudaStream_t stream_ = nullptr;
  Boundary boundary_values_{};
  float fixedTotal_ = 0.f;   // total of a boundary node
  int64_t t_ = 0;            // iterations done in this solve
  bool keepTotals_ = false;  // shift: the next step keeps the occupied nodes' totals
  int64_t totalsAt_ = -1;    // shift: the iteration whose occupied-node totals totals_ holds
  cuda::DeviceBuffer<float> coded_, values_;
  cuda::DeviceBuffer<int64_t> stored_, wood_;
  cuda::DeviceBuffer<unsigned> result_;
  // Push and pull: ping-pong state (pull: post values in pull_'s layout; totals_ before a checked step).
  cuda::DeviceBuffer<float> bufA_, bufB_;
  float* cur_ = nullptr;   // the current state (one of bufA_/bufB_)
  float* prev_ = nullptr;  // the previous state; the next step writes here
  // Shift: one state, occupied nodes' totals before a checked step, the node lists.
  cuda::DeviceBuffer<float> state_, totals_, leafCoded_, woodCoded_, boundaryCoded_;
  cuda::DeviceBuffer<int64_t> leaf_;
  cuda::DeviceBuffer<uint64_t> edge_, boundary_;  // empty / occupied boundary nodes, packed coordinates
  ShiftLists lists_{};
};

}  // namespace

std::unique_ptr<Solver> makeCudaSolver(const DenseLattice& lattice, int gpu, CudaScheme scheme) {
  return std::make_unique<CudaSolver>(lattice, gpu, scheme);
}

}  // namespace canopy::lb
