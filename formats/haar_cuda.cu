// haar_cuda.cu: ChaarDevice (see haar_cuda.h). The kernels call the CANOPY_HD functions of
// haar_view.h / haar_brick.h, the same code the CPU decoder runs.
#include "formats/haar_cuda.h"

#include "canopy/parallel_cuda.cuh"
#include "formats/haar_view.h"

namespace canopy::haar {
namespace {

template <class T>
T* uploadArray(const T* host, size_t count, size_t& bytes) {
  if (count == 0) return nullptr;
  T* dev = nullptr;
  CANOPY_CUDA_CHECK(cudaMalloc(&dev, count * sizeof(T)));
  CANOPY_CUDA_CHECK(cudaMemcpy(dev, host, count * sizeof(T), cudaMemcpyHostToDevice));
  bytes += count * sizeof(T);
  return dev;
}

__global__ void sampleKernel(ChaarView v, uint32_t base, const float* __restrict__ pts, size_t n,
                             float* __restrict__ out) {
  const size_t i = blockIdx.x * size_t(blockDim.x) + threadIdx.x;
  if (i >= n) return;
  const Rgb c = chaarSample(v, int(base), pts[3 * i], pts[3 * i + 1], pts[3 * i + 2]);
  out[3 * i] = c.r;
  out[3 * i + 1] = c.g;
  out[3 * i + 2] = c.b;
}

}  // namespace

ChaarDevice::ChaarDevice(const ChaarData& d) {
  view_ = d.view();
  try {
    slots_ = uploadArray(d.slots.data(), d.slots.size(), bytes_);
    records_ = uploadArray(d.records.data(), d.records.size(), bytes_);
    if (d.precision() == Precision::Quant) {
      quantRecords_ = uploadArray(d.quantRecords.data(), d.quantRecords.size(), bytes_);
      coefs_ = uploadArray(d.quantWords.data(), d.quantWords.size(), bytes_);
    } else if (d.precision() == Precision::Fp16)
      coefs_ = uploadArray(d.coefs16.data(), d.coefs16.size(), bytes_);
    else
      coefs_ = uploadArray(d.coefs32.data(), d.coefs32.size(), bytes_);
  } catch (...) {
    cudaFree(slots_);
    cudaFree(records_);
    cudaFree(coefs_);
    cudaFree(quantRecords_);
    throw;
  }
  view_.slots = slots_;
  view_.records = records_;
  view_.quantRecords = quantRecords_;
  view_.coefs = coefs_;
}

ChaarDevice::~ChaarDevice() {
  cudaFree(slots_);
  cudaFree(records_);
  cudaFree(quantRecords_);
  cudaFree(coefs_);
}

void ChaarDevice::sampleDevice(uint32_t base, const float* pts, size_t n, float* out, void* stream) const {
  if (n == 0) return;
  if (base >= view_.baseCount) throw usageError("ChaarDevice::sample: base out of range");
  const int block = 128;
  const size_t grid = (n + block - 1) / block;
  sampleKernel<<<unsigned(grid), block, 0, static_cast<cudaStream_t>(stream)>>>(view_, base, pts, n, out);
  CANOPY_CUDA_CHECK(cudaGetLastError());
}

void ChaarDevice::sample(uint32_t base, const float* ptsHost, size_t n, float* rgbHost) const {
  if (n == 0) return;
  cuda::DeviceBuffer<float> pts(3 * n), out(3 * n);
  pts.upload(ptsHost, 3 * n);
  sampleDevice(base, pts.data(), n, out.data());
  CANOPY_CUDA_CHECK(cudaDeviceSynchronize());
  out.download(rgbHost, 3 * n);
}

void ChaarDevice::decodeDense(uint32_t base, std::vector<float>& out) const {
  if (base >= view_.baseCount) throw usageError("ChaarDevice::decodeDense: base out of range");
  int64_t dim[3];
  for (int a = 0; a < 3; ++a) dim[a] = int64_t(view_.latticeMax[a]) - view_.latticeMin[a] + 1;
  const size_t cells = size_t(dim[0] * dim[1] * dim[2]);
  cuda::DeviceBuffer<float> dev(3 * cells);
  CANOPY_CUDA_CHECK(cudaMemset(dev.data(), 0, 3 * cells * sizeof(float)));
  const ChaarView v = view_;
  float* o = dev.data();
  const int64_t bricks = int64_t(v.brickDims[0]) * v.brickDims[1] * v.brickDims[2];
  const int64_t d0 = dim[0], d1 = dim[1], d2 = dim[2];
  cuda::parallelFor(bricks, [=] __device__(int64_t b) {
    const uint32_t slot = v.slots[b];
    if (slot == kEmptySlot) return;
    float vals[3][kBrickValues];
    if (!decodeSlot(v, int(base), slot, vals)) return;
    const int64_t bx = b % v.brickDims[0], by = b / v.brickDims[0] % v.brickDims[1],
                  bz = b / (int64_t(v.brickDims[0]) * v.brickDims[1]);
    for (int z = 0; z < kBrickCore; ++z)
      for (int y = 0; y < kBrickCore; ++y)
        for (int x = 0; x < kBrickCore; ++x) {
          const int64_t gx = bx * kBrickCore + x, gy = by * kBrickCore + y, gz = bz * kBrickCore + z;
          if (gx >= d0 || gy >= d1 || gz >= d2) continue;
          const int64_t c = 3 * ((gz * d1 + gy) * d0 + gx);
          const int i = brickIndex(x, y, z);
          o[c] = vals[0][i];
          o[c + 1] = vals[1][i];
          o[c + 2] = vals[2][i];
        }
  });
  CANOPY_CUDA_CHECK(cudaDeviceSynchronize());
  out.resize(3 * cells);
  dev.download(out.data(), 3 * cells);
}

}  // namespace canopy::haar
