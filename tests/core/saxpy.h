// saxpy.h: the trivial kernel that proves the dispatch layer: one CANOPY_HD functor, two backends.
#pragma once
#include <cstdint>
#include <vector>

#include "canopy/hd.h"

struct Saxpy {
  float a;
  const float* x;
  float* y;
  CANOPY_HD void operator()(int64_t i) const { y[i] = a * x[i] + y[i]; }
};

// Runs Saxpy over n elements on the GPU (saxpy_cuda.cu); only in CUDA builds.
void saxpyCuda(float a, const std::vector<float>& x, std::vector<float>& y);
// canopy::halfToFloat (value: canopy::halfValue) of all 65536 halves on the GPU, as float bits.
std::vector<uint32_t> halfToFloatAllCuda(bool value = false);
