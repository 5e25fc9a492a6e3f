// bench_haar_gpu: random trilinear lookups per second from compressed bricks (chaarSample, the
// device function a player kernel calls) vs the same decoded data uncompressed, as
//   (a) a 3D texture (cudaArray float4, hardware trilinear filtering), and
//   (b) a plain float3 array in global memory with the same software trilinear.
//   bench_haar_gpu IN.chaar [samples=16777216] [reps=10]
// Points are uniform over the stored bricks' cells (where a renderer samples: light exists there)
// and, second table, uniform over the whole lattice box. Each kernel's result is reduced to a
// checksum so nothing is optimised away; timings by cudaEvent, best of `reps`. Check (exit 3 when it
// fails): the GPU samples equal the CPU's bit for bit.
#include <cstdio>
#include <cstdlib>
#include <cmath>
#include <cstring>
#include <algorithm>
#include <random>
#include <string>
#include <vector>

#include "canopy/parallel_cuda.cuh"
#include "formats/haar_cuda.h"
#include "formats/haar_view.h"
#include "../bench_usage.h"

using namespace canopy::haar;

namespace {

// out == nullptr: timing (the sum keeps the sample live); else each sample is stored in out (rgb).
__global__ void compressedKernel(ChaarView v, int base, const float4* pts, size_t n, float* sum, float* out) {
  const size_t i = blockIdx.x * size_t(blockDim.x) + threadIdx.x;
  if (i >= n) return;
  const float4 p = pts[i];
  const Rgb c = chaarSample(v, base, p.x, p.y, p.z);
  if (out) {
    out[3 * i] = c.r;
    out[3 * i + 1] = c.g;
    out[3 * i + 2] = c.b;
    return;
  }
  const float s = c.r + c.g + c.b;
  if (s == -1.0f) atomicAdd(sum, s);  // never true for light; keeps the sample live
}

__global__ void textureKernel(cudaTextureObject_t tex, int3 mn, const float4* pts, size_t n, float* sum) {
  const size_t i = blockIdx.x * size_t(blockDim.x) + threadIdx.x;
  if (i >= n) return;
  const float4 p = pts[i];
  // Texel centres at +0.5 in CUDA's convention: index point (i,j,k) = texel (i,j,k).
  const float4 c = tex3D<float4>(tex, p.x - mn.x + 0.5f, p.y - mn.y + 0.5f, p.z - mn.z + 0.5f);
  const float s = c.x + c.y + c.z;
  if (s == -1.0f) atomicAdd(sum, s);
}

__global__ void arrayKernel(const float* __restrict__ dense, int3 mn, int3 mx, const float4* pts, size_t n, float* sum) {
  const size_t i = blockIdx.x * size_t(blockDim.x) + threadIdx.x;
  if (i >= n) return;
  const float4 p = pts[i];
  const float q[3] = {clampf(p.x, mn.x, mx.x), clampf(p.y, mn.y, mx.y), clampf(p.z, mn.z, mx.z)};
  const int d[3] = {mx.x - mn.x + 1, mx.y - mn.y + 1, mx.z - mn.z + 1};
  int ii[3];
  float f[3];
  const int m[3] = {mn.x, mn.y, mn.z};
  for (int a = 0; a < 3; ++a) {
    const float fl = floorf(q[a]);
    ii[a] = int(fl) - m[a];
    f[a] = q[a] - fl;
  }
  float s = 0;
  for (int ch = 0; ch < 3; ++ch) {
    float v[2][2][2];
    for (int dz = 0; dz < 2; ++dz)
      for (int dy = 0; dy < 2; ++dy)
        for (int dx = 0; dx < 2; ++dx) {
          const int x = ii[0] + dx, y = ii[1] + dy, z = ii[2] + dz;
          v[dz][dy][dx] = (x < d[0] && y < d[1] && z < d[2]) ? dense[3 * ((size_t(z) * d[1] + y) * d[0] + x) + ch] : 0.0f;
        }
    s += trilinear(v, f[0], f[1], f[2]);
  }
  if (s == -1.0f) atomicAdd(sum, s);
}

template <class Launch>
float bestMs(int reps, Launch launch) {
  cudaEvent_t a, b;
  cudaEventCreate(&a);
  cudaEventCreate(&b);
  launch();  // warm-up
  float best = 1e30f;
  for (int r = 0; r < reps; ++r) {
    cudaEventRecord(a);
    launch();
    cudaEventRecord(b);
    cudaEventSynchronize(b);
    float ms;
    cudaEventElapsedTime(&ms, a, b);
    best = std::min(best, ms);
  }
  CANOPY_CUDA_CHECK(cudaGetLastError());
  cudaEventDestroy(a);
  cudaEventDestroy(b);
  return best;
}

}  // namespace

constexpr char kUsage[] =
    "usage: bench_haar_gpu IN.chaar [samples] [reps]\n"
    "  Random trilinear lookups per second from the compressed bricks against a 3D texture and a plain\n"
    "  array of the decoded data (samples default 16777216, reps 10). Exit 3: GPU and CPU samples differ.\n";

int main(int argc, char** argv) {
  if (benchHelpRequested(argc, argv, kUsage)) return 0;
  if (argc < 2 || argc > 4 || argv[1][0] == '-') return benchUsageError("bench_haar_gpu", "expected IN.chaar [samples] [reps]", kUsage);
  try {
    const size_t n = argc > 2 ? size_t(std::atoll(argv[2])) : (size_t(1) << 24);
    const int reps = argc > 3 ? std::atoi(argv[3]) : 10;
    const ChaarData d = readChaar(argv[1]);
    const ChaarDevice dev(d);
    const ChaarHeader& h = d.header;
    const int3 mn = make_int3(h.latticeMin[0], h.latticeMin[1], h.latticeMin[2]);
    const int3 mx = make_int3(h.latticeMax[0], h.latticeMax[1], h.latticeMax[2]);
    const int dim[3] = {mx.x - mn.x + 1, mx.y - mn.y + 1, mx.z - mn.z + 1};
    cudaDeviceProp prop;
    CANOPY_CUDA_CHECK(cudaGetDeviceProperties(&prop, 0));
    std::printf("## canopy-haar GPU sampling: %s, %s, lattice %dx%dx%d, %u bases, %s, %zu samples, best of %d\n\n",
                prop.name, argv[1], dim[0], dim[1], dim[2], d.baseCount(),
                d.precision() == Precision::Quant ? "quant" : (d.precision() == Precision::Fp16 ? "fp16" : "fp32"), n, reps);

    // Point sets: (0) inside stored bricks, (1) uniform over the lattice box.
    std::vector<uint64_t> stored;
    for (uint64_t b = 0; b < d.brickCount(); ++b)
      if (d.slots[b] != kEmptySlot) stored.push_back(b);
    std::mt19937_64 rng(42);
    std::uniform_real_distribution<float> u01(0.0f, 1.0f);
    std::vector<float4> ptsHost[2];
    for (int set = 0; set < 2; ++set) {
      ptsHost[set].resize(n);
      for (size_t i = 0; i < n; ++i) {
        float p[3];
        if (set == 0 && !stored.empty()) {
          const uint64_t b = stored[rng() % stored.size()];
          const uint64_t bi[3] = {b % uint64_t(h.brickDims[0]), b / uint64_t(h.brickDims[0]) % uint64_t(h.brickDims[1]),
                                  b / (uint64_t(h.brickDims[0]) * h.brickDims[1])};
          for (int a = 0; a < 3; ++a) p[a] = float(h.latticeMin[a]) + float(3 * bi[a]) + 3.0f * u01(rng);
        } else {
          for (int a = 0; a < 3; ++a) p[a] = float(h.latticeMin[a]) + float(dim[a] - 1) * u01(rng);
        }
        ptsHost[set][i] = make_float4(p[0], p[1], p[2], 0.0f);
      }
    }
    // What a sample reads (point set 0, all bases): the kept coefficients its footprint depends on.
    {
      double need = 0, kept = 0, haarSamples = 0, raw = 0, fast = 0, none = 0;
      const ChaarView hv = d.view();
      const size_t m = std::min<size_t>(n, size_t(1) << 20);
      for (uint32_t b = 0; b < d.baseCount(); ++b)
        for (size_t i = 0; i < m; ++i) {
          const BrickLookup at = locate(hv, ptsHost[0][i].x, ptsHost[0][i].y, ptsHost[0][i].z);
          const BrickRecord rec = at.slot == kEmptySlot ? BrickRecord{} : hv.records[uint64_t(b) * hv.slotCount + at.slot];
          const uint64_t mask = rec.mask();
          if (mask == 0) ++none;
          else if (rec.raw()) ++raw;
          else if (mask == 1) ++fast;
          else {
            ++haarSamples;
            kept += popcount64(mask);
            need += popcount64(mask & footprintNeedMask(at.lx, at.ly, at.lz));
          }
        }
      const double all = double(m) * d.baseCount();
      std::printf("samples in stored bricks, all bases: %.1f%% no light, %.1f%% raw bricks, %.1f%% average-only, "
                  "%.1f%% Haar bricks with on average %.2f kept coefficients of which the footprint needs %.2f\n\n",
                  100 * none / all, 100 * raw / all, 100 * fast / all, 100 * haarSamples / all,
                  kept / std::max(1.0, haarSamples), need / std::max(1.0, haarSamples));
    }

    canopy::cuda::DeviceBuffer<float4> pts(n);
    canopy::cuda::DeviceBuffer<float> sum(1);
    const size_t nCpu = std::min<size_t>(n, 65536);  // samples checked against the CPU
    canopy::cuda::DeviceBuffer<float> outDev(3 * nCpu);
    std::vector<float> outGpu(3 * nCpu);
    size_t mismatchCpu = 0;
    const unsigned grid = unsigned((n + 127) / 128), gridCheck = unsigned((nCpu + 127) / 128);
    std::printf("| points | base | compressed Gsamples/s | texture Gsamples/s | array Gsamples/s | compressed / texture |\n");
    std::printf("|---|---|---|---|---|---|\n");
    for (int set = 0; set < 2; ++set) {
      pts.upload(ptsHost[set].data(), n);
      double totC = 0, totT = 0, totA = 0;
      for (uint32_t b = 0; b < d.baseCount(); ++b) {
        std::vector<float> dense;
        decodeBaseDense(d, b, dense);
        // Texture: float4 cudaArray with linear filtering, clamp addressing.
        std::vector<float4> rgba(dense.size() / 3);
        for (size_t i = 0; i < rgba.size(); ++i) rgba[i] = make_float4(dense[3 * i], dense[3 * i + 1], dense[3 * i + 2], 0);
        cudaArray_t arr;
        const cudaChannelFormatDesc desc = cudaCreateChannelDesc<float4>();
        const cudaExtent ext = make_cudaExtent(size_t(dim[0]), size_t(dim[1]), size_t(dim[2]));
        CANOPY_CUDA_CHECK(cudaMalloc3DArray(&arr, &desc, ext));
        cudaMemcpy3DParms cp = {};
        cp.srcPtr = make_cudaPitchedPtr(rgba.data(), size_t(dim[0]) * sizeof(float4), size_t(dim[0]), size_t(dim[1]));
        cp.dstArray = arr;
        cp.extent = ext;
        cp.kind = cudaMemcpyHostToDevice;
        CANOPY_CUDA_CHECK(cudaMemcpy3D(&cp));
        cudaResourceDesc rd = {};
        rd.resType = cudaResourceTypeArray;
        rd.res.array.array = arr;
        cudaTextureDesc td = {};
        td.addressMode[0] = td.addressMode[1] = td.addressMode[2] = cudaAddressModeBorder;
        td.filterMode = cudaFilterModeLinear;
        td.readMode = cudaReadModeElementType;
        cudaTextureObject_t tex;
        CANOPY_CUDA_CHECK(cudaCreateTextureObject(&tex, &rd, &td, nullptr));
        canopy::cuda::DeviceBuffer<float> denseDev(dense.size());
        denseDev.upload(dense.data(), dense.size());

        const ChaarView v = dev.view();
        // Correctness: the GPU's samples are the CPU's, bit for bit.
        compressedKernel<<<gridCheck, 128>>>(v, int(b), pts.data(), nCpu, sum.data(), outDev.data());
        outDev.download(outGpu.data(), outGpu.size());
        const ChaarView hv = d.view();
        for (size_t i = 0; i < nCpu; ++i) {
          const Rgb c = chaarSample(hv, int(b), ptsHost[set][i].x, ptsHost[set][i].y, ptsHost[set][i].z);
          mismatchCpu += std::memcmp(&c.r, &outGpu[3 * i], 4) != 0 || std::memcmp(&c.g, &outGpu[3 * i + 1], 4) != 0 ||
                         std::memcmp(&c.b, &outGpu[3 * i + 2], 4) != 0;
        }
        const float msC = bestMs(reps, [&] { compressedKernel<<<grid, 128>>>(v, int(b), pts.data(), n, sum.data(), nullptr); });
        const float msT = bestMs(reps, [&] { textureKernel<<<grid, 128>>>(tex, mn, pts.data(), n, sum.data()); });
        const float msA = bestMs(reps, [&] { arrayKernel<<<grid, 128>>>(denseDev.data(), mn, mx, pts.data(), n, sum.data()); });
        totC += msC;
        totT += msT;
        totA += msA;
        auto rate = [&](double ms) { return ms > 0 ? n / (ms * 1e6) : 0.0; };
        if (b % 6 == 0 || b + 1 == d.baseCount())
          std::printf("| %s | %s | %.2f | %.2f | %.2f | %.2fx |\n", set == 0 ? "stored bricks" : "lattice box",
                      baseName(b).c_str(), rate(msC), rate(msT), rate(msA), msT / msC);
        cudaDestroyTextureObject(tex);
        cudaFreeArray(arr);
      }
      const double nb = double(n) * d.baseCount();
      auto rate = [&](double ms) { return ms > 0 ? nb / (ms * 1e6) : 0.0; };
      std::printf("| %s | **all %u** | **%.2f** | **%.2f** | **%.2f** | **%.2fx** (target >= 0.5x) |\n",
                  set == 0 ? "stored bricks" : "lattice box", d.baseCount(), rate(totC), rate(totT), rate(totA), totT / totC);
    }
    std::printf("\ncheck: GPU != CPU (bits) in %zu samples (of %zu per base and point set)\n", mismatchCpu, nCpu);
    std::printf("\ncompressed on device: %.2f MiB; dense float4 texture per base: %.2f MiB\n",
                double(dev.deviceBytes()) / (1 << 20), double(dim[0]) * dim[1] * dim[2] * 16 / (1 << 20));
    return mismatchCpu ? 3 : 0;
  } catch (const canopy::Error& e) {
    std::fprintf(stderr, "bench_haar_gpu: error: %s\n", e.what());
    return int(e.code());
  }
}
