// device_cuda.cu: GPU discovery for a CUDA build.
#include <cuda_runtime.h>

namespace canopy {
int cudaDeviceCountImpl() {
  int n = 0;
  if (cudaGetDeviceCount(&n) != cudaSuccess) {
    cudaGetLastError();  // clear the sticky "no device"/"no driver" error
    return 0;
  }
  return n;
}
}  // namespace canopy
