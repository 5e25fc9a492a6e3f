// bench_lbsolve_streams: does the ACCESS PATTERN of the D3Q19 push update alone cap its bandwidth,
// and which layout would reach >= 80% of the copy bandwidth? Prints a Markdown table on stdout.
//
//   bench_lbsolve_streams [--sizes 128,256] [--reps 20] [--json FILE]
//
// The push kernel (tools/lbsolve/collide.h updateLanes, solve_cuda.cu pushLeafKernel) moves 156 B
// per node update: 19 float reads (structure of arrays, state[m*n + idx], idx = (z*N + y)*N + x),
// 19 float writes to the neighbour r + c_m (interior targets only) and one float density read; one
// thread per node, blocks of 128 threads along x, grid (ceil(N/128), N, N). It reaches 53-59% of the
// cudaMemcpy device-to-device bandwidth on an H100/H200. Every variant below keeps that traffic and
// drops the collision arithmetic. Each size N (cubic, n = N^3 nodes): warm-up once, then the best
// (minimum) of --reps launches timed with cudaEvents. Nominal bytes: 19 floats read + 19 written per
// node (152 B), + 4 B where the variant reads the density, whatever a variant actually skips (pull:
// boundary threads; push: boundary targets). "of copy" = achieved GB/s / the bandwidth of a 1 GiB
// cudaMemcpy D2D measured in the same run (best of 10, read + write = 2 GiB per copy).
//
// Load/store order. In the per-m variants (soa-push and every variant derived from it) each thread
// loads value m, stores it, then loads m + 1: one load in flight per thread (two in soa-push-2y).
// The order is forced by a false dependency: load m + 1's address adds the sign bit of value m
// (always 0 here), so it cannot issue before value m has arrived. Written plainly (or with a compiler
// barrier) ptxas hoists the read-only loads above the stores and the kernel becomes the staged one
// (seen with cuobjdump -sass). The "-stage" variants load all 19 values into registers first and then
// store them, the real kernel's order (its collision needs all 19): 19 loads in flight per thread.
// Loads are volatile inline PTX (ld.global.nc = LDG.E.CONSTANT, what a const __restrict__ input
// usually compiles to) so that the compiler neither drops nor predicates them: every source node
// reads all 19 values, as updateLanes does before its collision.
//
// After timing, sample nodes are copied back and checked against the pattern (`in` holds a value
// that encodes (m, idx)); a mismatch exits 1. No CUDA device: exit 2.
#include <cuda_runtime.h>

#include <algorithm>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <random>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

// The D3Q19 directions c_m in the project's order (plain header: constexpr + CANOPY_HD only).
#include "canopy/lattice_dirs.h"

using canopy::lattice::dir;
using canopy::lattice::kQ;

#define CHECK(call)                                                                                       \
  do {                                                                                                    \
    const cudaError_t err_ = (call);                                                                      \
    if (err_ != cudaSuccess) {                                                                            \
      std::fprintf(stderr, "%s:%d: %s: %s\n", __FILE__, __LINE__, #call, cudaGetErrorString(err_));       \
      std::exit(1);                                                                                       \
    }                                                                                                     \
  } while (0)

namespace {

constexpr int kBlockX = 128;       // threads along x per block, as pushLeafKernel
constexpr float kSentinel = -1.f;  // `out` before each variant: targets never written keep it
// Padding between consecutive arrays of the "-pad" layout: stride = roundUp(n, 32) + 1056 floats,
// i.e. + 4224 B = 33 x 128 B: every array still starts on a 128-byte line, but consecutive arrays
// are no longer a power of two apart (at N = 128 the plain SoA arrays are exactly 8 MiB apart, so
// all 19 streams of a warp would start in the same DRAM partition / channel: partition camping).
constexpr int64_t kPadFloats = 1056;

// The value of (m, idx) in `in`: an integer below 2^24 (18 + 32 * (2^19 - 1)), exact in float.
__host__ __device__ inline float encode(int m, int64_t idx) { return float(m + 32 * int(idx & ((1 << 19) - 1))); }

// Structure of arrays, array m at m * stride (stride = n: the project's layout; larger: padded).
struct SoA {
  int64_t stride;
  __host__ __device__ int64_t at(int m, int64_t idx) const { return m * stride + idx; }
};
// Array of structure of arrays: tiles of 32 consecutive nodes (32 consecutive x; N % 32 == 0), the
// tile's 19 arrays of 32 floats contiguous (2432 B): a warp's 19 loads are one contiguous block.
template <int T>
struct AoSoAT {
  __host__ __device__ int64_t at(int m, int64_t idx) const { return ((idx / T) * kQ + m) * T + idx % T; }
};
using AoSoA = AoSoAT<32>;

__device__ __forceinline__ float load(const float* p) {
  float v;
  asm volatile("ld.global.nc.f32 %0, [%1];" : "=f"(v) : "l"(p));
  return v;
}
__device__ __forceinline__ void fence() { asm volatile("" ::: "memory"); }  // compiler-only barrier
// The per-m chain: 0 for every value >= 0 (all values of `in`), but unknown to the compiler.
__device__ __forceinline__ int64_t after(float v) { return __float_as_int(v) >> 31; }
__device__ __forceinline__ bool inside(int v, int N) { return v >= 1 && v <= N - 2; }

// ---- Kernels -------------------------------------------------------------------------------------

// copy-float4: a grid-stride copy of `count` floats (the whole state buffer: 76n B read, 76n written).
__global__ void copy4Kernel(const float* __restrict__ in, float* __restrict__ out, int64_t count) {
  const int64_t t = int64_t(blockIdx.x) * blockDim.x + threadIdx.x, step = int64_t(gridDim.x) * blockDim.x;
  const int64_t count4 = count / 4;
  const float4* in4 = reinterpret_cast<const float4*>(in);
  float4* out4 = reinterpret_cast<float4*>(out);
  for (int64_t i = t; i < count4; i += step) out4[i] = in4[i];
  if (t < count - 4 * count4) out[4 * count4 + t] = in[4 * count4 + t];
}

// soa-aligned: out[m*n + idx] = in[m*n + idx] for every node and m: the 19 streams without the shift
// and without the density (per-m order, or all loads first with Staged).
template <bool Staged>
__global__ void alignedKernel(int N, const float* __restrict__ in, float* __restrict__ out) {
  const int x = int(blockIdx.x) * kBlockX + int(threadIdx.x);
  if (x >= N) return;
  const int64_t n = int64_t(N) * N * N, idx = (int64_t(blockIdx.z) * N + blockIdx.y) * N + x;
  float f[kQ];
  int64_t dep = 0;
#pragma unroll
  for (int m = 0; m < kQ; ++m) {
    f[m] = load(in + m * n + idx + dep);
    if (!Staged) out[m * n + idx] = f[m], dep = after(f[m]);
  }
  if (Staged) {
    fence();
#pragma unroll
    for (int m = 0; m < kQ; ++m) out[m * n + idx] = f[m];
  }
}

// The push pattern of updateLanes: node r reads its 19 values and writes value m to r + c_m in
// `out` if that target is interior (every node a source), after reading its density and testing it
// like pushLeafKernel's wood test (never true here: the density is 0.5). Rows = 2: each thread does
// nodes y and y + 1 (same x), both nodes' loads of m before their stores: two loads in flight per m.
// blockDim.y = 2 (soa-push-b256): 256-thread blocks over two y rows.
template <class Lay, bool Staged, int Rows>
__global__ void pushKernel(Lay lay, int N, const float* __restrict__ coded, const float* __restrict__ in,
                           float* __restrict__ out) {
  const int x = int(blockIdx.x) * kBlockX + int(threadIdx.x);
  const int y0 = int(blockIdx.y * blockDim.y + threadIdx.y) * Rows, z = int(blockIdx.z);
  if (x >= N || y0 >= N) return;
  const int64_t nn = int64_t(N) * N;
  int64_t idx[Rows];
  bool on[Rows];
#pragma unroll
  for (int r = 0; r < Rows; ++r) {
    on[r] = y0 + r < N;
    idx[r] = (z * int64_t(N) + y0 + r) * N + x;
    if (on[r] && load(coded + idx[r]) < 0.f) return;
  }
  float f[kQ][Rows];
  int64_t dep = 0;
  if (Staged) {
#pragma unroll
    for (int m = 0; m < kQ; ++m)
#pragma unroll
      for (int r = 0; r < Rows; ++r) f[m][r] = on[r] ? load(in + lay.at(m, idx[r])) : 0.f;
    fence();
  }
#pragma unroll
  for (int m = 0; m < kQ; ++m) {
    if (!Staged) {
#pragma unroll
      for (int r = 0; r < Rows; ++r) f[m][r] = on[r] ? load(in + lay.at(m, idx[r]) + dep) : 0.f;
      dep = 0;
#pragma unroll
      for (int r = 0; r < Rows; ++r) dep += after(f[m][r]);
    }
    const int cx = dir(m, 0), cy = dir(m, 1), cz = dir(m, 2);
    const int64_t off = cx + cy * int64_t(N) + cz * nn;
#pragma unroll
    for (int r = 0; r < Rows; ++r)
      if (on[r] && inside(x + cx, N) && inside(y0 + r + cy, N) && inside(z + cz, N))
        out[lay.at(m, idx[r] + off)] = f[m][r];
  }
}

// The pull pattern: interior node r reads value m from r - c_m and writes it to r itself (boundary
// threads return at once), after the density read and test. Writes are aligned, reads shifted.
// Cs: the stores with the streaming cache hint (st.global.cs, evict first).
template <class Lay, bool Staged, bool Cs = false>
__global__ void pullKernel(Lay lay, int N, const float* __restrict__ coded, const float* __restrict__ in,
                           float* __restrict__ out) {
  const int x = int(blockIdx.x) * kBlockX + int(threadIdx.x), y = int(blockIdx.y), z = int(blockIdx.z);
  if (!inside(x, N) || !inside(y, N) || !inside(z, N)) return;
  const int64_t nn = int64_t(N) * N, idx = (z * int64_t(N) + y) * N + x;
  if (load(coded + idx) < 0.f) return;
  float f[kQ];
  int64_t dep = 0;
#pragma unroll
  for (int m = 0; m < kQ; ++m) {
    f[m] = load(in + lay.at(m, idx - (dir(m, 0) + dir(m, 1) * int64_t(N) + dir(m, 2) * nn)) + dep);
    if (!Staged) out[lay.at(m, idx)] = f[m], dep = after(f[m]);
  }
  if (Staged) {
    fence();
#pragma unroll
    for (int m = 0; m < kQ; ++m) {
      if (Cs) {
        __stcs(out + lay.at(m, idx), f[m]);
      } else {
        out[lay.at(m, idx)] = f[m];
      }
    }
  }
}

template <class Lay>
__global__ void encodeKernel(Lay lay, int64_t n, float* __restrict__ buf) {
  for (int64_t i = int64_t(blockIdx.x) * blockDim.x + threadIdx.x; i < n; i += int64_t(gridDim.x) * blockDim.x)
    for (int m = 0; m < kQ; ++m) buf[lay.at(m, i)] = encode(m, i);
}

__global__ void setKernel(float* __restrict__ buf, int64_t count, float v) {
  for (int64_t i = int64_t(blockIdx.x) * blockDim.x + threadIdx.x; i < count; i += int64_t(gridDim.x) * blockDim.x)
    buf[i] = v;
}

__global__ void gatherKernel(const float* __restrict__ buf, const int64_t* __restrict__ at, int k,
                             float* __restrict__ values) {
  const int i = int(blockIdx.x) * blockDim.x + int(threadIdx.x);
  if (i < k) values[i] = buf[at[i]];
}

// ---- Host ----------------------------------------------------------------------------------------

int ceilDiv(int64_t a, int64_t b) { return int((a + b - 1) / b); }

struct Row {
  std::string name;
  int N;
  double us, bytes, gbps, fraction;
};

// What `out` must hold after a variant: Copy = out[k] == in[k] (the SoA buffer copied flat);
// Aligned = (m, idx) at every node; Shift = (m, t - c_m) at interior targets t, the sentinel at
// boundary nodes (push and pull give the same result).
enum class Pattern { Copy, Aligned, Shift };

struct Sample {
  int64_t at;
  float expect;
};

struct Bench {
  int N = 0, reps = 20, sms = 0, threadsPerSm = 0;
  int64_t n = 0, cap = 0;  // nodes, floats per state buffer
  float *in = nullptr, *out = nullptr, *coded = nullptr;
  double copyGBs = 0;  // the 1 GiB cudaMemcpy reference, GB/s
  std::vector<Row> rows;
  std::mt19937_64 rng{12345};
};

template <class Launch>
float bestMs(int reps, Launch&& launch) {
  cudaEvent_t e0, e1;
  CHECK(cudaEventCreate(&e0));
  CHECK(cudaEventCreate(&e1));
  launch();  // warm-up
  CHECK(cudaDeviceSynchronize());
  float best = 1e30f;
  for (int r = 0; r < reps; ++r) {
    CHECK(cudaEventRecord(e0));
    launch();
    CHECK(cudaEventRecord(e1));
    CHECK(cudaEventSynchronize(e1));
    float ms = 0;
    CHECK(cudaEventElapsedTime(&ms, e0, e1));
    best = std::min(best, ms);
  }
  CHECK(cudaEventDestroy(e0));
  CHECK(cudaEventDestroy(e1));
  return best;
}

template <class Lay>
std::vector<Sample> samplesOf(Bench& b, Pattern p, Lay lay) {
  const int N = b.N;
  std::vector<Sample> s;
  auto coord = [&](int lo, int hi) { return lo + int(b.rng() % uint64_t(hi - lo + 1)); };
  if (p == Pattern::Copy) {
    for (int i = 0; i < 256; ++i) {
      const int64_t k = int64_t(b.rng() % uint64_t(kQ * b.n));
      s.push_back({k, encode(int(k / b.n), k % b.n)});
    }
    return s;
  }
  for (int i = 0; i < 80; ++i) {
    int x = coord(1, N - 2), y = coord(1, N - 2), z = coord(1, N - 2);
    const bool edge = i >= 64;  // the last 16: boundary nodes (one coordinate 0 or N - 1)
    if (edge) (i % 3 == 0 ? x : i % 3 == 1 ? y : z) = (i & 1) ? N - 1 : 0;
    const int64_t idx = (int64_t(z) * N + y) * N + x;
    for (int m = 0; m < kQ; ++m) {
      const int64_t src = idx - (dir(m, 0) + dir(m, 1) * int64_t(N) + dir(m, 2) * int64_t(N) * N);
      const float e = p == Pattern::Aligned ? encode(m, idx) : (edge ? kSentinel : encode(m, src));
      s.push_back({lay.at(m, idx), e});
    }
  }
  return s;
}

void verify(const Bench& b, const char* name, const std::vector<Sample>& s) {
  const int k = int(s.size());
  std::vector<int64_t> at(k);
  std::vector<float> got(k);
  for (int i = 0; i < k; ++i) at[i] = s[i].at;
  int64_t* dAt = nullptr;
  float* dVal = nullptr;
  CHECK(cudaMalloc(&dAt, k * sizeof(int64_t)));
  CHECK(cudaMalloc(&dVal, k * sizeof(float)));
  CHECK(cudaMemcpy(dAt, at.data(), k * sizeof(int64_t), cudaMemcpyHostToDevice));
  gatherKernel<<<ceilDiv(k, 256), 256>>>(b.out, dAt, k, dVal);
  CHECK(cudaGetLastError());
  CHECK(cudaMemcpy(got.data(), dVal, k * sizeof(float), cudaMemcpyDeviceToHost));
  CHECK(cudaFree(dAt));
  CHECK(cudaFree(dVal));
  for (int i = 0; i < k; ++i)
    if (got[i] != s[i].expect) {
      std::fprintf(stderr, "bench_lbsolve_streams: %s at N=%d is WRONG: out[%lld] = %.1f, expected %.1f\n", name,
                   b.N, (long long)s[i].at, got[i], s[i].expect);
      std::exit(1);
    }
}

// One variant: `in` filled in layout `lay` (gaps and `out`: the sentinel), timed, checked, printed.
template <class Lay, class Launch>
void run(Bench& b, const char* name, Lay lay, bool density, Pattern p, Launch&& launch) {
  const int blocks = b.sms * 4;
  setKernel<<<blocks, 256>>>(b.in, b.cap, kSentinel);
  setKernel<<<blocks, 256>>>(b.out, b.cap, kSentinel);
  encodeKernel<<<blocks, 256>>>(lay, b.n, b.in);
  CHECK(cudaGetLastError());
  CHECK(cudaDeviceSynchronize());
  const double ms = bestMs(b.reps, launch);
  verify(b, name, samplesOf(b, p, lay));
  Row r{name, b.N, ms * 1e3, double(b.n) * (2 * kQ * 4 + (density ? 4 : 0)), 0, 0};
  r.gbps = r.bytes / (ms * 1e-3) / 1e9;
  r.fraction = r.gbps / b.copyGBs;
  std::printf("| %-20s | %4d | %10.1f | %12.0f | %7.1f | %6.3f |\n", name, r.N, r.us, r.bytes, r.gbps, r.fraction);
  std::fflush(stdout);
  b.rows.push_back(r);
}

void runSize(Bench& b) {
  const int N = b.N;
  const int64_t n = b.n;
  const SoA soa{n}, pad{(n + 31) / 32 * 32 + kPadFloats};
  const AoSoA tiles;
  const dim3 blk(kBlockX), blk2(kBlockX, 2);
  const dim3 grid(ceilDiv(N, kBlockX), N, N), grid2(ceilDiv(N, kBlockX), ceilDiv(N, 2), N);  // grid2: 2 rows a y
  auto push = [&](auto kernel, auto lay, dim3 g, dim3 k) {
    return [&b, kernel, lay, g, k, N]() {
      kernel<<<g, k>>>(lay, N, b.coded, b.in, b.out);
      CHECK(cudaGetLastError());
    };
  };
  auto pull = [&](auto kernel, auto lay) { return push(kernel, lay, grid, blk); };

  // memcpy and copy-float4 copy one whole state buffer (19n floats): the same 152n nominal bytes.
  run(b, "memcpy", soa, false, Pattern::Copy,
      [&] { CHECK(cudaMemcpyAsync(b.out, b.in, kQ * n * sizeof(float), cudaMemcpyDeviceToDevice)); });
  run(b, "copy-float4", soa, false, Pattern::Copy, [&] {
    copy4Kernel<<<b.sms * (b.threadsPerSm / 256), 256>>>(b.in, b.out, kQ * n);
    CHECK(cudaGetLastError());
  });
  run(b, "soa-aligned", soa, false, Pattern::Aligned, [&] {
    alignedKernel<false><<<grid, blk>>>(N, b.in, b.out);
    CHECK(cudaGetLastError());
  });
  run(b, "soa-aligned-stage", soa, false, Pattern::Aligned, [&] {
    alignedKernel<true><<<grid, blk>>>(N, b.in, b.out);
    CHECK(cudaGetLastError());
  });
  run(b, "soa-push", soa, true, Pattern::Shift, push(pushKernel<SoA, false, 1>, soa, grid, blk));
  run(b, "soa-pull", soa, true, Pattern::Shift, pull(pullKernel<SoA, false>, soa));
  run(b, "soa-push-pad", pad, true, Pattern::Shift, push(pushKernel<SoA, false, 1>, pad, grid, blk));
  run(b, "soa-pull-pad", pad, true, Pattern::Shift, pull(pullKernel<SoA, false>, pad));
  if (N % 32 == 0) {
    run(b, "aosoa-push", tiles, true, Pattern::Shift, push(pushKernel<AoSoA, false, 1>, tiles, grid, blk));
    run(b, "aosoa-pull", tiles, true, Pattern::Shift, pull(pullKernel<AoSoA, false>, tiles));
  } else {
    std::printf("| aosoa-*: skipped, N %% 32 != 0 |\n");
  }
  run(b, "soa-push-b256", soa, true, Pattern::Shift, push(pushKernel<SoA, false, 1>, soa, grid2, blk2));
  run(b, "soa-push-2y", soa, true, Pattern::Shift, push(pushKernel<SoA, false, 2>, soa, grid2, blk));
  // The real kernel's order (all loads, then all stores), then the layouts above in that order.
  run(b, "soa-push-stage", soa, true, Pattern::Shift, push(pushKernel<SoA, true, 1>, soa, grid, blk));
  run(b, "soa-pull-stage", soa, true, Pattern::Shift, pull(pullKernel<SoA, true>, soa));
  run(b, "soa-push-pad-stage", pad, true, Pattern::Shift, push(pushKernel<SoA, true, 1>, pad, grid, blk));
  run(b, "soa-pull-pad-stage", pad, true, Pattern::Shift, pull(pullKernel<SoA, true>, pad));
  if (N % 32 == 0) {
    run(b, "aosoa-push-stage", tiles, true, Pattern::Shift, push(pushKernel<AoSoA, true, 1>, tiles, grid, blk));
    run(b, "aosoa-pull-stage", tiles, true, Pattern::Shift, pull(pullKernel<AoSoA, true>, tiles));
    // Tiles of 64, 128 and 256 nodes (a direction's run of a block: 256 B, 512 B, 512 B), and the
    // stores with the streaming hint. A last partial tile stays inside the buffer (its padding,
    // kPadFloats per direction, exceeds 256 nodes).
    run(b, "aosoa-pull-stage-cs", tiles, true, Pattern::Shift, pull(pullKernel<AoSoA, true, true>, tiles));
    run(b, "aosoa64-pull-stage", AoSoAT<64>{}, true, Pattern::Shift, pull(pullKernel<AoSoAT<64>, true>, AoSoAT<64>{}));
    run(b, "aosoa128-pull-stage", AoSoAT<128>{}, true, Pattern::Shift, pull(pullKernel<AoSoAT<128>, true>, AoSoAT<128>{}));
    run(b, "aosoa256-pull-stage", AoSoAT<256>{}, true, Pattern::Shift, pull(pullKernel<AoSoAT<256>, true>, AoSoAT<256>{}));
  }
}

// 1 GiB cudaMemcpy device to device, best of 10, bytes read + written per second (GB/s).
double copyReference() {
  const size_t bytes = size_t(1) << 30;
  void *a = nullptr, *c = nullptr;
  CHECK(cudaMalloc(&a, bytes));
  CHECK(cudaMalloc(&c, bytes));
  CHECK(cudaMemset(a, 1, bytes));
  CHECK(cudaMemset(c, 0, bytes));
  const float ms = bestMs(10, [&] { CHECK(cudaMemcpyAsync(c, a, bytes, cudaMemcpyDeviceToDevice)); });
  CHECK(cudaFree(a));
  CHECK(cudaFree(c));
  return 2.0 * double(bytes) / (ms * 1e-3) / 1e9;
}

const char* const kUsage =
    "usage: bench_lbsolve_streams [--sizes 128,256] [--reps 20] [--json FILE]\n"
    "  Times the memory traffic of the D3Q19 push update (no collision) in several layouts and orders\n"
    "  against cudaMemcpy device-to-device. Exit 0 ok, 1 error or wrong result, 2 no CUDA device.\n";

}  // namespace

int main(int argc, char** argv) {
  std::vector<int> sizes{128, 256};
  int reps = 20;
  std::string json;
  for (int i = 1; i < argc; ++i) {
    const std::string k = argv[i];
    if (k == "--help" || k == "-h") {
      std::fputs(kUsage, stdout);
      return 0;
    }
    if (i + 1 >= argc || (k != "--sizes" && k != "--reps" && k != "--json")) {
      std::fprintf(stderr, "bench_lbsolve_streams: bad argument '%s'\n%s", k.c_str(), kUsage);
      return 1;
    }
    const std::string v = argv[++i];
    try {
      if (k == "--sizes") {
        sizes.clear();
        std::stringstream ss(v);
        for (std::string w; std::getline(ss, w, ',');)
          if (!w.empty()) sizes.push_back(std::stoi(w));
      } else if (k == "--reps") {
        reps = std::stoi(v);
      } else {
        json = v;
      }
    } catch (const std::exception&) {
      std::fprintf(stderr, "bench_lbsolve_streams: bad value '%s' for %s\n%s", v.c_str(), k.c_str(), kUsage);
      return 1;
    }
  }
  if (reps < 1 || std::any_of(sizes.begin(), sizes.end(), [](int s) { return s < 4 || s > 1024; })) {
    std::fprintf(stderr, "bench_lbsolve_streams: need --reps >= 1 and sizes in 4..1024\n");
    return 1;
  }

  int devices = 0;
  const cudaError_t e = cudaGetDeviceCount(&devices);
  if (e != cudaSuccess || devices == 0) {
    std::fprintf(stderr, "bench_lbsolve_streams: no CUDA device (%s)\n",
                 e != cudaSuccess ? cudaGetErrorString(e) : "device count is 0");
    return 2;
  }
  CHECK(cudaSetDevice(0));
  cudaDeviceProp prop;
  CHECK(cudaGetDeviceProperties(&prop, 0));
  int memClockKHz = 0;  // cudaDeviceProp::memoryClockRate is gone in CUDA 13: use the attribute
  CHECK(cudaDeviceGetAttribute(&memClockKHz, cudaDevAttrMemoryClockRate, 0));
  const double peak = 2.0 * memClockKHz * 1e3 * (prop.memoryBusWidth / 8.0) / 1e9;  // double data rate
  Bench b;
  b.reps = reps;
  b.sms = prop.multiProcessorCount;
  b.threadsPerSm = prop.maxThreadsPerMultiProcessor;
  b.copyGBs = copyReference();
  std::printf("device: %s, %d SMs, memory clock %d MHz x %d-bit bus: theoretical peak %.1f GB/s\n", prop.name, b.sms,
              memClockKHz / 1000, prop.memoryBusWidth, peak);
  std::printf("cudaMemcpy D2D 1 GiB (read + write, best of 10): %.1f GB/s = %.3f of peak; reps %d\n\n", b.copyGBs,
              b.copyGBs / peak, reps);
  std::printf("| %-20s | %4s | %10s | %12s | %7s | %6s |\n", "variant", "N", "us/launch", "bytes/launch", "GB/s",
              "of copy");
  std::printf("|%s|------|------------|--------------|---------|---------|\n", std::string(22, '-').c_str());

  for (int N : sizes) {
    b.N = N;
    b.n = int64_t(N) * N * N;
    b.cap = kQ * ((b.n + 31) / 32 * 32 + kPadFloats);  // the largest layout (padded SoA)
    CHECK(cudaMalloc(&b.in, b.cap * sizeof(float)));
    CHECK(cudaMalloc(&b.out, b.cap * sizeof(float)));
    CHECK(cudaMalloc(&b.coded, b.n * sizeof(float)));
    setKernel<<<b.sms * 4, 256>>>(b.coded, b.n, 0.5f);  // a leaf density: the wood test is never true
    CHECK(cudaGetLastError());
    runSize(b);
    CHECK(cudaFree(b.in));
    CHECK(cudaFree(b.out));
    CHECK(cudaFree(b.coded));
  }

  if (!json.empty()) {
    FILE* f = std::fopen(json.c_str(), "w");
    if (!f) {
      std::fprintf(stderr, "bench_lbsolve_streams: cannot write %s\n", json.c_str());
      return 1;
    }
    std::fprintf(f, "[\n");
    for (size_t i = 0; i < b.rows.size(); ++i) {
      const Row& r = b.rows[i];
      std::fprintf(f,
                   "  {\"variant\": \"%s\", \"N\": %d, \"us\": %.3f, \"bytes\": %.0f, \"gbps\": %.2f, "
                   "\"of_copy\": %.4f, \"copy_gbps\": %.2f, \"peak_gbps\": %.2f}%s\n",
                   r.name.c_str(), r.N, r.us, r.bytes, r.gbps, r.fraction, b.copyGBs, peak,
                   i + 1 < b.rows.size() ? "," : "");
    }
    std::fprintf(f, "]\n");
    std::fclose(f);
  }
  return 0;
}
