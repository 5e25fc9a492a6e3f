#include "canopy/parallel_cuda.cuh"
#include "saxpy.h"

void saxpyCuda(float a, const std::vector<float>& x, std::vector<float>& y) {
  canopy::cuda::DeviceBuffer<float> dx(x.size()), dy(y.size());
  dx.upload(x.data(), x.size());
  dy.upload(y.data(), y.size());
  canopy::cuda::parallelFor(int64_t(x.size()), Saxpy{a, dx.data(), dy.data()});
  CANOPY_CUDA_CHECK(cudaDeviceSynchronize());
  dy.download(y.data(), y.size());
}
