// device.cpp: --device parsing and GPU discovery.
#include "canopy/device.h"

#include <cstdlib>

#include "canopy/errors.h"

namespace canopy {

#ifdef CANOPY_HAS_CUDA
int cudaDeviceCountImpl();  // device_cuda.cu
bool builtWithCuda() { return true; }
int cudaDeviceCount() {
  static const int n = cudaDeviceCountImpl();
  return n;
}
#else
bool builtWithCuda() { return false; }
int cudaDeviceCount() { return 0; }
#endif

std::string Device::str() const {
  if (kind == Kind::Cpu) return "cpu";
  return index < 0 ? "cuda" : "cuda:" + std::to_string(index);
}

Device resolveDevice(const std::string& spec) {
  Device d;
  if (spec == "auto") {
    if (cudaDeviceCount() > 0) {
      d.kind = Device::Kind::Cuda;
      d.index = -1;
    }
    return d;
  }
  if (spec == "cpu") return d;
  if (spec == "cuda" || spec.rfind("cuda:", 0) == 0) {
    if (!builtWithCuda())
      throw unsupported("--device " + spec + ": this build of Canopy has no CUDA backend");
    int n = cudaDeviceCount();
    if (n == 0) throw unsupported("--device " + spec + ": no CUDA GPU is available");
    d.kind = Device::Kind::Cuda;
    d.index = -1;
    if (spec.size() > 4) {
      const std::string num = spec.substr(5);
      char* end = nullptr;
      long v = std::strtol(num.c_str(), &end, 10);
      if (num.empty() || *end != '\0' || v < 0)
        throw usageError("--device " + spec + ": expected cuda:N with N a GPU index");
      if (v >= n)
        throw unsupported("--device " + spec + ": only " + std::to_string(n) + " GPU(s) present");
      d.index = int(v);
    }
    return d;
  }
  throw usageError("--device " + spec + ": expected auto, cpu, cuda or cuda:N");
}

}  // namespace canopy
