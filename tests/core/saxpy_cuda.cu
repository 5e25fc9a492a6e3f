#include "canopy/parallel_cuda.cuh"
#include "canopy/half.h"
#include "saxpy.h"

namespace {
struct HalfToFloatAll {
  uint32_t* bits;
  bool value;  // canopy::halfValue instead of canopy::halfToFloat
  __device__ void operator()(int64_t i) const {
    const uint16_t h = uint16_t(i);
    bits[i] = __float_as_uint(value ? canopy::halfValue(h) : canopy::halfToFloat(h));
  }
};
}  // namespace

std::vector<uint32_t> halfToFloatAllCuda(bool value) {
  std::vector<uint32_t> out(65536);
  canopy::cuda::DeviceBuffer<uint32_t> d(out.size());
  canopy::cuda::parallelFor(int64_t(out.size()), HalfToFloatAll{d.data(), value});
  CANOPY_CUDA_CHECK(cudaDeviceSynchronize());
  d.download(out.data(), out.size());
  return out;
}

void saxpyCuda(float a, const std::vector<float>& x, std::vector<float>& y) {
  canopy::cuda::DeviceBuffer<float> dx(x.size()), dy(y.size());
  dx.upload(x.data(), x.size());
  dy.upload(y.data(), y.size());
  canopy::cuda::parallelFor(int64_t(x.size()), Saxpy{a, dx.data(), dy.data()});
  CANOPY_CUDA_CHECK(cudaDeviceSynchronize());
  dy.download(y.data(), y.size());
}
