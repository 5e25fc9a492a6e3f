// sample_plant.h: Canopy's built-in procedural plant, written as a glTF binary by the project.
//
// A tapered trunk and branches (material "bark", opaque) and alpha-masked leaf cards (material
// "leaves", alphaMode MASK, alphaCutoff 0.5, a generated 64x64 RGBA PNG whose alpha is the leaf
// shape). Deterministic: the same bytes on every run and machine (fixed integer RNG, stb's PNG
// writer, nlohmann's JSON). Used by the demo (`canopy-voxelize --write-sample`) and by tests.
#pragma once
#include <cstdint>
#include <string>
#include <vector>

namespace canopy {

struct SamplePlantOptions {
  int branches = 6;
  int leavesPerBranch = 24;
  uint32_t seed = 1;
};

std::vector<uint8_t> samplePlantGlb(const SamplePlantOptions& options = {});
// Writes samplePlantGlb() atomically.
void writeSamplePlant(const std::string& path, const SamplePlantOptions& options = {});

// Helpers shared with tests that build small glTF files: a GLB container from a JSON document
// and one binary chunk (padded as the spec requires), and RGBA8 -> PNG bytes.
std::vector<uint8_t> makeGlb(const std::string& json, const std::vector<uint8_t>& bin);
std::vector<uint8_t> encodePng(int width, int height, const std::vector<uint8_t>& rgba);

}  // namespace canopy
