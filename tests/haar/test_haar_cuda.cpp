// The CUDA decoder against the CPU decoder: bit for bit (fp32, fp16 and quantised coefficients), 19 bases,
// random points everywhere (inside, on brick seams, outside the lattice) and every lattice cell.
// Skips without a GPU. Set CANOPY_HAAR_LIGHT_VDB=path/to/plant.light.vdb to use a real lbsolve
// output instead of the synthetic field (bench/run-gpu.sh, phase tests, does both).
#include <gtest/gtest.h>

#include <cstdlib>
#include <cstring>
#include <random>

#include "canopy/device.h"
#include "formats/haar_cuda.h"
#include "haar.h"
#include "synthetic_light.h"

using namespace canopy::haar;
using namespace canopy::haar::testing;

namespace {

ChaarData lightFile(Precision p, float threshold) {
  const char* path = std::getenv("CANOPY_HAAR_LIGHT_VDB");
  if (path && *path) {
    const LightFieldPtr f = openLightField(path);
    const LatticeGeom& g = lightGeom(*f);
    ChaarAssembly a;
    a.geom = g;
    a.precision = p;
    a.threshold = threshold;
    std::vector<DenseLight> keep;
    for (uint32_t b = 0; b < lightBaseCount(*f); ++b) {
      std::array<int32_t, 3> dir;
      const DenseLight light = lightBase(*f, b, dir);
      LiftedBase lb(g, light, p, path);
      // (Quant: the threshold is the step; at least the smallest step the base's levels fit.)
      a.codes.push_back(lb.encode(p == Precision::Quant ? std::max(threshold, lb.minQuantStep()) : threshold));
      if (p == Precision::Quant) a.threshold = -1;  // per base
      a.directions.push_back(dir);
      a.valueMax.push_back(lb.valueMax());
    }
    return assembleChaar(a);
  }
  const LatticeGeom g = makeGeom(40, 37, 35, -20, 0, -17);
  std::vector<DenseLight> lights;
  for (uint32_t b = 0; b < 19; ++b) lights.push_back(b % 5 == 4 ? randomLight(g, b) : smoothLight(g, b));
  return encodeLights(g, lights, threshold, -1.0f, p);
}

void compareAll(const ChaarData& d) {
  ChaarDevice dev(d);
  const ChaarView host = d.view();
  std::mt19937 rng(3);
  const int n = 200000;
  std::vector<float> pts(3 * size_t(n));
  for (int i = 0; i < n; ++i)
    for (int a = 0; a < 3; ++a) {
      const float lo = float(d.header.latticeMin[a]) - 1.5f, hi = float(d.header.latticeMax[a]) + 1.5f;
      float v = std::uniform_real_distribution<float>(lo, hi)(rng);
      if (i % 4 == 0) v = std::round(v / 3) * 3 + float(d.header.latticeMin[a] % 3);  // brick seams
      pts[3 * size_t(i) + size_t(a)] = v;
    }
  std::vector<float> gpu(3 * size_t(n)), cpuDense, gpuDense;
  for (uint32_t b = 0; b < d.baseCount(); ++b) {
    dev.sample(b, pts.data(), size_t(n), gpu.data());
    for (int i = 0; i < n; ++i) {
      const Rgb c = chaarSample(host, int(b), pts[3 * size_t(i)], pts[3 * size_t(i) + 1], pts[3 * size_t(i) + 2]);
      ASSERT_EQ(std::memcmp(&c.r, &gpu[3 * size_t(i)], 4), 0) << "base " << b << " point " << i;
      ASSERT_EQ(std::memcmp(&c.g, &gpu[3 * size_t(i) + 1], 4), 0) << "base " << b << " point " << i;
      ASSERT_EQ(std::memcmp(&c.b, &gpu[3 * size_t(i) + 2], 4), 0) << "base " << b << " point " << i;
    }
    decodeBaseDense(d, b, cpuDense);
    dev.decodeDense(b, gpuDense);
    ASSERT_EQ(cpuDense.size(), gpuDense.size());
    ASSERT_EQ(std::memcmp(cpuDense.data(), gpuDense.data(), cpuDense.size() * 4), 0) << "base " << b;
  }
}

}  // namespace

TEST(HaarCuda, cuda_DecodeEqualsCpuBitForBitFp32) {
  if (canopy::cudaDeviceCount() == 0) GTEST_SKIP() << "no CUDA device";
  compareAll(lightFile(Precision::Fp32, 0.003f));
  compareAll(lightFile(Precision::Fp32, 0.0f));
}

TEST(HaarCuda, cuda_DecodeEqualsCpuBitForBitFp16) {
  if (canopy::cudaDeviceCount() == 0) GTEST_SKIP() << "no CUDA device";
  compareAll(lightFile(Precision::Fp16, 0.003f));
}

TEST(HaarCuda, cuda_DecodeEqualsCpuBitForBitQuant) {
  if (canopy::cudaDeviceCount() == 0) GTEST_SKIP() << "no CUDA device";
  compareAll(lightFile(Precision::Quant, 0.003f));
  compareAll(lightFile(Precision::Quant, 0.03f));
  compareAll(lightFile(Precision::Quant, 0.0f));  // the finest steps: fields wider than two words
}
