// sample_cuda.h: samples a packed model on the GPU through the same CANOPY_HD functions as the CPU
// (canopyDescend + canopySampleBrick). Defined in sample_cuda.cu (CUDA builds only).
#pragma once
#include <vector>

#include "formats/canopy_file.h"

namespace canopy::octreepack::testing {

// Uploads the model's tiles and all its brick (and light) pages, samples each unit-space point
// (xyz triples) at maxLevel, returns the samples; with `lightRgb`, also base `lightBase` of the
// lighting (3 floats per point; 0 where the node has no brick or the model no light).
std::vector<CanopySample> sampleOnCuda(const CanopyFile& file, uint32_t model, const std::vector<float>& points,
                                       uint32_t maxLevel, std::vector<float>* lightRgb = nullptr, uint32_t lightBase = 0);

}  // namespace canopy::octreepack::testing
