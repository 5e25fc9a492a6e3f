// parallel_cuda.cuh: the CUDA side of the dispatch layer (include from .cu files only).
//
// canopy::cuda::parallelFor(n, f) launches f(i) for i in [0, n) as a grid-stride kernel; f is the
// same CANOPY_HD functor the CPU path runs. CANOPY_CUDA_CHECK turns CUDA errors into
// canopy::Error(Runtime) with the call and location.
#pragma once
#include <cstdint>
#include <string>

#include <cuda_runtime.h>

#include "canopy/errors.h"

#define CANOPY_CUDA_CHECK(call)                                                              \
  do {                                                                                       \
    cudaError_t canopy_err_ = (call);                                                        \
    if (canopy_err_ != cudaSuccess)                                                          \
      throw ::canopy::runtimeError(std::string("CUDA error: ") + cudaGetErrorString(canopy_err_) + \
                                   " in " #call " at " __FILE__ ":" + std::to_string(__LINE__)); \
  } while (0)

namespace canopy::cuda {

template <class F>
__global__ void parallelForKernel(int64_t n, F f) {
  for (int64_t i = blockIdx.x * int64_t(blockDim.x) + threadIdx.x; i < n;
       i += int64_t(gridDim.x) * blockDim.x)
    f(i);
}

template <class F>
void parallelFor(int64_t n, F f, cudaStream_t stream = 0, int blockSize = 256) {
  if (n <= 0) return;
  int64_t blocks = (n + blockSize - 1) / blockSize;
  if (blocks > 65535LL * 32) blocks = 65535LL * 32;
  parallelForKernel<<<unsigned(blocks), blockSize, 0, stream>>>(n, f);
  CANOPY_CUDA_CHECK(cudaGetLastError());
}

// RAII device buffer.
template <class T>
class DeviceBuffer {
 public:
  DeviceBuffer() = default;
  explicit DeviceBuffer(size_t count) { resize(count); }
  ~DeviceBuffer() { if (ptr_) cudaFree(ptr_); }
  DeviceBuffer(const DeviceBuffer&) = delete;
  DeviceBuffer& operator=(const DeviceBuffer&) = delete;
  DeviceBuffer(DeviceBuffer&& o) noexcept : ptr_(o.ptr_), count_(o.count_) { o.ptr_ = nullptr; o.count_ = 0; }
  void resize(size_t count) {
    if (ptr_) cudaFree(ptr_);
    ptr_ = nullptr;
    count_ = count;
    if (count) CANOPY_CUDA_CHECK(cudaMalloc(&ptr_, count * sizeof(T)));
  }
  void upload(const T* host, size_t count) { CANOPY_CUDA_CHECK(cudaMemcpy(ptr_, host, count * sizeof(T), cudaMemcpyHostToDevice)); }
  void download(T* host, size_t count) const { CANOPY_CUDA_CHECK(cudaMemcpy(host, ptr_, count * sizeof(T), cudaMemcpyDeviceToHost)); }
  T* data() { return ptr_; }
  const T* data() const { return ptr_; }
  size_t size() const { return count_; }

 private:
  T* ptr_ = nullptr;
  size_t count_ = 0;
};

}  // namespace canopy::cuda
