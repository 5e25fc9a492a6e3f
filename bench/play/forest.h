// forest.h: the benchmark's scenes, built in-process (no OpenVDB, no assets needed): synthetic
// plants (tests/octreepack/synthetic.h) scattered like pipelines/scatter.py does (uniform on a disk
// in the ground plane, random yaw about +Y, uniform scale), deterministic for a seed.
#pragma once
#include <cmath>
#include <cstdint>
#include <random>
#include <vector>

#include "formats/canopy_file.h"

namespace canopy::play::bench {

struct ScatterOptions {
  uint32_t count = 400;
  uint32_t models = 3;
  float radius = 40.0f;       // metres
  float scaleMin = 0.8f, scaleMax = 1.3f;
  uint32_t seed = 1;
};

inline std::vector<CanopyInstance> scatterInstances(const ScatterOptions& o) {
  std::mt19937 rng(o.seed);
  std::uniform_real_distribution<float> u01(0.0f, 1.0f);
  std::vector<CanopyInstance> out;
  out.reserve(o.count);
  for (uint32_t i = 0; i < o.count; ++i) {
    const float r = o.radius * std::sqrt(u01(rng)), theta = 6.2831853f * u01(rng);
    const float yaw = 6.2831853f * u01(rng);
    const float s = o.scaleMin + (o.scaleMax - o.scaleMin) * u01(rng);
    CanopyInstance in{};
    const float c = std::cos(yaw) * s, sn = std::sin(yaw) * s;
    const float m[12] = {c, 0, sn, r * std::cos(theta), 0, s, 0, 0, -sn, 0, c, r * std::sin(theta)};
    for (int k = 0; k < 12; ++k) in.modelToWorld[k] = m[k];
    in.model = uint32_t(u01(rng) * float(o.models)) % o.models;
    out.push_back(in);
  }
  return out;
}

}  // namespace canopy::play::bench
