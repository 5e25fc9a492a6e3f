#include "canopy/parallel_cuda.cuh"
#include "canopy/half.h"
#include "saxpy.h"

namespace {
struct HalfToFloatAll {
  uint32_t* bits;
  __device__ void operator()(int64_t i) const { bits[i] = __float_as_uint(canopy::halfToFloat(uint16_t(i))); }
};
}  // namespace

std::vector<uint32_t> halfToFloatAllCuda() {
  std::vector<uint32_t> out(65536);
  canopy::cuda::DeviceBuffer<uint32_t> d(out.size());
  canopy::cuda::parallelFor(int64_t(out.size()), HalfToFloatAll{d.data()});
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
