// sample_plant.cpp: see sample_plant.h.
#include "sample_plant.h"

#include <stb_image_write.h>

#include <array>
#include <cmath>
#include <cstring>
#include <nlohmann/json.hpp>

#include "canopy/atomic_file.h"
#include "canopy/errors.h"

namespace canopy {
namespace {

using V3 = std::array<double, 3>;
V3 add(V3 a, V3 b) { return {a[0] + b[0], a[1] + b[1], a[2] + b[2]}; }
V3 sub(V3 a, V3 b) { return {a[0] - b[0], a[1] - b[1], a[2] - b[2]}; }
V3 mul(V3 a, double s) { return {a[0] * s, a[1] * s, a[2] * s}; }
V3 cross(V3 a, V3 b) { return {a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]}; }
V3 normalize(V3 a) {
  const double l = std::sqrt(a[0] * a[0] + a[1] * a[1] + a[2] * a[2]);
  return mul(a, 1.0 / l);
}

// xorshift32: the same sequence everywhere.
struct Rng {
  uint32_t s;
  double next() {
    s ^= s << 13;
    s ^= s >> 17;
    s ^= s << 5;
    return double(s >> 8) / double(1u << 24);
  }
  double range(double a, double b) { return a + (b - a) * next(); }
};

struct Primitive {
  std::vector<float> pos, uv;
  std::vector<uint32_t> idx;
  uint32_t vertex(V3 p) {
    for (double c : p) pos.push_back(float(c));
    return uint32_t(pos.size() / 3 - 1);
  }
};

// Open tapered cylinder from a to b (radii ra, rb), `seg` sides, `rings` segments along the axis.
void cylinder(Primitive& m, V3 a, V3 b, double ra, double rb, int seg, int rings) {
  const V3 axis = normalize(sub(b, a));
  const V3 helper = std::fabs(axis[1]) < 0.9 ? V3{0, 1, 0} : V3{1, 0, 0};
  const V3 u = normalize(cross(axis, helper)), w = cross(axis, u);
  const uint32_t first = uint32_t(m.pos.size() / 3);
  for (int r = 0; r <= rings; ++r) {
    const double t = double(r) / rings, rad = ra + (rb - ra) * t;
    const V3 c = add(a, mul(sub(b, a), t));
    for (int s = 0; s < seg; ++s) {
      const double ang = 2 * M_PI * s / seg;
      m.vertex(add(c, add(mul(u, rad * std::cos(ang)), mul(w, rad * std::sin(ang)))));
    }
  }
  for (int r = 0; r < rings; ++r)
    for (int s = 0; s < seg; ++s) {
      const uint32_t i0 = first + uint32_t(r * seg + s), i1 = first + uint32_t(r * seg + (s + 1) % seg);
      const uint32_t j0 = i0 + uint32_t(seg), j1 = i1 + uint32_t(seg);
      m.idx.insert(m.idx.end(), {i0, i1, j1, i0, j1, j0});
    }
}

// A leaf card: base at p, pointing along dir, facing roughly `normal`; uv v runs base -> tip.
void leaf(Primitive& m, V3 p, V3 dir, V3 normal, double length, double width) {
  const V3 side = mul(normalize(cross(dir, normal)), width / 2);
  const V3 tip = add(p, mul(dir, length));
  const uint32_t a = m.vertex(sub(p, side)), b = m.vertex(add(p, side));
  const uint32_t c = m.vertex(add(tip, side)), d = m.vertex(sub(tip, side));
  m.uv.insert(m.uv.end(), {0, 1, 1, 1, 1, 0, 0, 0});
  m.idx.insert(m.idx.end(), {a, b, c, a, c, d});
}

// 64x64 RGBA leaf: an opaque pointed ellipse with a darker midrib on a transparent background.
std::vector<uint8_t> leafTexture(int n) {
  std::vector<uint8_t> px(size_t(n) * size_t(n) * 4);
  for (int y = 0; y < n; ++y)
    for (int x = 0; x < n; ++x) {
      const double u = (x + 0.5) / n - 0.5, v = (y + 0.5) / n;  // v: 0 at the tip, 1 at the base
      const double halfWidth = 0.46 * std::sin(M_PI * std::min(1.0, v * 1.05));
      const bool inside = std::fabs(u) < halfWidth && v > 0.02 && v < 0.98;
      const bool rib = std::fabs(u) < 0.025;
      uint8_t* p = &px[(size_t(y) * size_t(n) + size_t(x)) * 4];
      p[0] = rib ? 70 : 60;
      p[1] = rib ? 110 : uint8_t(120 + 40 * v);
      p[2] = rib ? 40 : 35;
      p[3] = inside ? 255 : 0;
    }
  return px;
}

void pad4(std::vector<uint8_t>& b, uint8_t fill) {
  while (b.size() % 4) b.push_back(fill);
}

}  // namespace

std::vector<uint8_t> encodePng(int width, int height, const std::vector<uint8_t>& rgba) {
  std::vector<uint8_t> out;
  auto sink = [](void* ctx, void* data, int size) {
    auto* o = static_cast<std::vector<uint8_t>*>(ctx);
    o->insert(o->end(), static_cast<uint8_t*>(data), static_cast<uint8_t*>(data) + size);
  };
  if (!stbi_write_png_to_func(sink, &out, width, height, 4, rgba.data(), width * 4))
    throw runtimeError("PNG encoding failed");
  return out;
}

std::vector<uint8_t> makeGlb(const std::string& json, const std::vector<uint8_t>& bin) {
  std::vector<uint8_t> j(json.begin(), json.end());
  pad4(j, ' ');
  std::vector<uint8_t> b = bin;
  pad4(b, 0);
  std::vector<uint8_t> out;
  auto u32 = [&](uint32_t v) {
    for (int i = 0; i < 4; ++i) out.push_back(uint8_t(v >> (8 * i)));
  };
  const uint32_t total = uint32_t(12 + 8 + j.size() + (b.empty() ? 0 : 8 + b.size()));
  u32(0x46546C67u);  // "glTF"
  u32(2);
  u32(total);
  u32(uint32_t(j.size()));
  u32(0x4E4F534Au);  // "JSON"
  out.insert(out.end(), j.begin(), j.end());
  if (!b.empty()) {
    u32(uint32_t(b.size()));
    u32(0x004E4942u);  // "BIN\0"
    out.insert(out.end(), b.begin(), b.end());
  }
  return out;
}

namespace {

// The plant's geometry: a trunk, o.branches branches with their leaves, and a crown tuft.
void growPlant(const SamplePlantOptions& o, Primitive& bark, Primitive& leaves) {
  Rng rng{o.seed ? o.seed : 1};
  const double trunkHeight = 2.0;
  cylinder(bark, {0, 0, 0}, {0, trunkHeight, 0}, 0.12, 0.05, 12, 6);
  const double golden = M_PI * (3 - std::sqrt(5.0));
  for (int bi = 0; bi < o.branches; ++bi) {
    const double h = trunkHeight * (0.45 + 0.5 * (bi + 0.5) / o.branches);
    const double yaw = bi * golden + rng.range(-0.2, 0.2);
    const double tilt = rng.range(0.55, 0.85);  // radians above horizontal
    const V3 dir = normalize({std::cos(yaw) * std::cos(tilt), std::sin(tilt), std::sin(yaw) * std::cos(tilt)});
    const double len = 0.9 * (1.1 - 0.5 * double(bi) / o.branches);
    const V3 a{0, h, 0}, b = add(a, mul(dir, len));
    cylinder(bark, a, b, 0.035, 0.012, 8, 3);
    for (int li = 0; li < o.leavesPerBranch; ++li) {
      const double t = 0.25 + 0.75 * (li + rng.next()) / o.leavesPerBranch;
      const V3 p = add(a, mul(sub(b, a), t));
      const V3 out = normalize({rng.range(-1, 1), rng.range(-0.2, 1), rng.range(-1, 1)});
      const V3 ldir = normalize(add(mul(dir, 0.5), out));
      const V3 nrm = normalize({rng.range(-0.3, 0.3), 1, rng.range(-0.3, 0.3)});
      leaf(leaves, p, ldir, nrm, rng.range(0.14, 0.2), rng.range(0.08, 0.11));
    }
  }
  // A crown tuft at the top of the trunk.
  for (int li = 0; li < o.leavesPerBranch; ++li) {
    const double yaw = li * golden;
    const V3 dir = normalize({std::cos(yaw), rng.range(0.3, 1.2), std::sin(yaw)});
    leaf(leaves, {0, trunkHeight, 0}, dir, {0, 1, 0}, rng.range(0.14, 0.2), rng.range(0.08, 0.11));
  }
}

// The binary chunk under construction, with its buffer views and accessors.
struct GlbBuffers {
  std::vector<uint8_t> bin;
  nlohmann::json views = nlohmann::json::array(), accessors = nlohmann::json::array();

  // Appends bytes as a buffer view (4-byte aligned); returns its index.
  int addView(const void* data, size_t bytes) {
    pad4(bin, 0);
    views.push_back({{"buffer", 0}, {"byteOffset", bin.size()}, {"byteLength", bytes}});
    bin.insert(bin.end(), static_cast<const uint8_t*>(data), static_cast<const uint8_t*>(data) + bytes);
    return int(views.size() - 1);
  }
  // A VEC3 float accessor with its bounds; returns its index.
  int addPositions(const std::vector<float>& p) {
    std::array<float, 3> lo{1e30f, 1e30f, 1e30f}, hi{-1e30f, -1e30f, -1e30f};
    for (size_t i = 0; i < p.size(); ++i) {
      lo[i % 3] = std::min(lo[i % 3], p[i]);
      hi[i % 3] = std::max(hi[i % 3], p[i]);
    }
    const int v = addView(p.data(), p.size() * 4);
    accessors.push_back({{"bufferView", v}, {"componentType", 5126}, {"count", p.size() / 3},
                         {"type", "VEC3"}, {"min", lo}, {"max", hi}});
    return int(accessors.size() - 1);
  }
  // A float accessor of `comps` components per element; returns its index.
  int addFloats(const std::vector<float>& p, int comps, const char* type) {
    const int v = addView(p.data(), p.size() * 4);
    accessors.push_back({{"bufferView", v}, {"componentType", 5126}, {"count", p.size() / size_t(comps)}, {"type", type}});
    return int(accessors.size() - 1);
  }
  // A uint32 index accessor; returns its index.
  int addIndices(const std::vector<uint32_t>& idx) {
    const int v = addView(idx.data(), idx.size() * 4);
    accessors.push_back({{"bufferView", v}, {"componentType", 5125}, {"count", idx.size()}, {"type", "SCALAR"}});
    return int(accessors.size() - 1);
  }
};

}  // namespace

std::vector<uint8_t> samplePlantGlb(const SamplePlantOptions& o) {
  Primitive bark, leaves;
  growPlant(o, bark, leaves);

  // Binary chunk: bark positions, bark indices, leaf positions, leaf uvs, leaf indices, PNG.
  GlbBuffers buf;
  const int barkPos = buf.addPositions(bark.pos), barkIdx = buf.addIndices(bark.idx);
  const int leafPos = buf.addPositions(leaves.pos), leafUv = buf.addFloats(leaves.uv, 2, "VEC2");
  const int leafIdx = buf.addIndices(leaves.idx);
  const std::vector<uint8_t> png = encodePng(64, 64, leafTexture(64));
  const int pngView = buf.addView(png.data(), png.size());

  nlohmann::json doc = {
      {"asset", {{"version", "2.0"}, {"generator", "canopy-voxelize sample plant"}}},
      {"scene", 0},
      {"scenes", {{{"name", "sample"}, {"nodes", {0}}}}},
      {"nodes", {{{"name", "sample_plant"}, {"mesh", 0}}}},
      {"meshes", {{{"name", "sample_plant"},
                   {"primitives", {{{"attributes", {{"POSITION", barkPos}}}, {"indices", barkIdx}, {"material", 0}},
                                   {{"attributes", {{"POSITION", leafPos}, {"TEXCOORD_0", leafUv}}},
                                    {"indices", leafIdx}, {"material", 1}}}}}}},
      {"materials", {{{"name", "bark"},
                      {"pbrMetallicRoughness", {{"baseColorFactor", {0.25, 0.16, 0.09, 1.0}}, {"metallicFactor", 0.0}}}},
                     {{"name", "leaves"}, {"alphaMode", "MASK"}, {"alphaCutoff", 0.5}, {"doubleSided", true},
                      {"pbrMetallicRoughness", {{"baseColorTexture", {{"index", 0}}}, {"metallicFactor", 0.0}}}}}},
      {"textures", {{{"source", 0}, {"sampler", 0}}}},
      {"samplers", {{{"magFilter", 9729}, {"minFilter", 9729}, {"wrapS", 33071}, {"wrapT", 33071}}}},
      {"images", {{{"name", "leaf"}, {"mimeType", "image/png"}, {"bufferView", pngView}}}},
      {"bufferViews", buf.views},
      {"accessors", buf.accessors},
  };
  pad4(buf.bin, 0);
  doc["buffers"] = {{{"byteLength", buf.bin.size()}}};
  return makeGlb(doc.dump(), buf.bin);
}

void writeSamplePlant(const std::string& path, const SamplePlantOptions& o) {
  const std::vector<uint8_t> bytes = samplePlantGlb(o);
  writeFileAtomic(path, bytes.data(), bytes.size());
}

}  // namespace canopy
