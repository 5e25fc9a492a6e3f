// sample_cuda.h: samples a packed model on the GPU through the same CANOPY_HD functions as the CPU
// (canopyDescend + canopySampleBrick). Defined in sample_cuda.cu (CUDA builds only).
#pragma once
#include <vector>

#include "formats/canopy_file.h"

namespace canopy::octreepack::testing {

// Uploads the model's tiles and all its brick pages, samples each unit-space point (xyz triples)
// at maxLevel, returns the samples.
std::vector<CanopySample> sampleOnCuda(const CanopyFile& file, uint32_t model, const std::vector<float>& points,
                                       uint32_t maxLevel);

}  // namespace canopy::octreepack::testing
