// test_helpers.h: small meshes and glTF files built in memory for the voxelize tests.
#pragma once
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <functional>
#include <fstream>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "mesh_io.h"
#include "sample_plant.h"

namespace canopy::test {

inline mesh::Mesh emptyMesh() {
  mesh::Mesh m;
  mesh::Material mat;
  mat.name = "leaves";
  m.materials.push_back(mat);
  return m;
}

inline void addTriangle(mesh::Mesh& m, mesh::Vec3 a, mesh::Vec3 b, mesh::Vec3 c, int material = 0) {
  mesh::Triangle t;
  t.p = {a, b, c};
  t.material = material;
  m.triangles.push_back(t);
}

// Axis-aligned box surface [lo, hi] as 12 triangles.
inline void addBox(mesh::Mesh& m, mesh::Vec3 lo, mesh::Vec3 hi) {
  auto P = [&](int x, int y, int z) {
    return mesh::Vec3{x ? hi[0] : lo[0], y ? hi[1] : lo[1], z ? hi[2] : lo[2]};
  };
  const int faces[6][4][3] = {{{0, 0, 0}, {0, 1, 0}, {0, 1, 1}, {0, 0, 1}}, {{1, 0, 0}, {1, 0, 1}, {1, 1, 1}, {1, 1, 0}},
                              {{0, 0, 0}, {0, 0, 1}, {1, 0, 1}, {1, 0, 0}}, {{0, 1, 0}, {1, 1, 0}, {1, 1, 1}, {0, 1, 1}},
                              {{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0}}, {{0, 0, 1}, {0, 1, 1}, {1, 1, 1}, {1, 0, 1}}};
  for (auto& f : faces) {
    const mesh::Vec3 q[4] = {P(f[0][0], f[0][1], f[0][2]), P(f[1][0], f[1][1], f[1][2]),
                             P(f[2][0], f[2][1], f[2][2]), P(f[3][0], f[3][1], f[3][2])};
    addTriangle(m, q[0], q[1], q[2]);
    addTriangle(m, q[0], q[2], q[3]);
  }
}

// UV sphere of radius r about c: `rings` latitude bands, `segs` longitudes (vertices on the sphere).
inline void addSphere(mesh::Mesh& m, mesh::Vec3 c, double r, int rings, int segs) {
  auto P = [&](int i, int j) {
    const double th = M_PI * i / rings, ph = 2 * M_PI * j / segs;
    return mesh::Vec3{c[0] + r * std::sin(th) * std::cos(ph), c[1] + r * std::cos(th),
                      c[2] + r * std::sin(th) * std::sin(ph)};
  };
  for (int i = 0; i < rings; ++i)
    for (int j = 0; j < segs; ++j) {
      const auto a = P(i, j), b = P(i + 1, j), cc = P(i + 1, j + 1), d = P(i, j + 1);
      if (i != rings - 1) addTriangle(m, a, b, cc);
      if (i != 0) addTriangle(m, a, cc, d);
    }
}

// A minimal glTF: one mesh of float positions + uint32 indices (one node, optional extra JSON).
struct GltfParts {
  nlohmann::json doc;
  std::vector<uint8_t> bin;
};

inline GltfParts triangleGltf(const std::vector<float>& pos, const std::vector<uint32_t>& idx) {
  GltfParts g;
  g.bin.resize(pos.size() * 4 + idx.size() * 4);
  std::memcpy(g.bin.data(), pos.data(), pos.size() * 4);
  std::memcpy(g.bin.data() + pos.size() * 4, idx.data(), idx.size() * 4);
  g.doc = {
      {"asset", {{"version", "2.0"}}},
      {"scene", 0},
      {"scenes", {{{"nodes", {0}}}}},
      {"nodes", {{{"mesh", 0}}}},
      {"meshes", {{{"primitives", {{{"attributes", {{"POSITION", 0}}}, {"indices", 1}}}}}}},
      {"buffers", {{{"byteLength", g.bin.size()}}}},
      {"bufferViews", {{{"buffer", 0}, {"byteOffset", 0}, {"byteLength", pos.size() * 4}},
                       {{"buffer", 0}, {"byteOffset", pos.size() * 4}, {"byteLength", idx.size() * 4}}}},
      {"accessors", {{{"bufferView", 0}, {"componentType", 5126}, {"count", pos.size() / 3}, {"type", "VEC3"}},
                     {{"bufferView", 1}, {"componentType", 5125}, {"count", idx.size()}, {"type", "SCALAR"}}}},
  };
  return g;
}

inline std::vector<uint8_t> toGlb(const GltfParts& g) { return makeGlb(g.doc.dump(), g.bin); }

inline void writeBytes(const std::string& path, const std::vector<uint8_t>& b) {
  std::ofstream f(path, std::ios::binary | std::ios::trunc);
  f.write(reinterpret_cast<const char*>(b.data()), std::streamsize(b.size()));
}

inline void writeText(const std::string& path, const std::string& s) {
  std::ofstream f(path, std::ios::binary | std::ios::trunc);
  f << s;
}

inline std::vector<uint8_t> readBytes(const std::string& path) {
  std::ifstream f(path, std::ios::binary);
  return std::vector<uint8_t>((std::istreambuf_iterator<char>(f)), std::istreambuf_iterator<char>());
}

// A fresh scratch directory per test binary.
inline std::string scratchDir(const std::string& name) {
  const std::string d = std::string(CANOPY_BINARY_DIR) + "/test-scratch/" + name;
  std::string cmd = "rm -rf '" + d + "' && mkdir -p '" + d + "'";
  if (std::system(cmd.c_str()) != 0) std::abort();
  return d;
}

}  // namespace canopy::test
