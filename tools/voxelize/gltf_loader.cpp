// gltf_loader.cpp: glTF 2.0 (.gltf/.glb) -> mesh::Mesh, through tinygltf compiled with Draco.
//
// tinygltf parses the JSON, loads buffers and images (stb_image) and decodes Draco primitives; it
// does not bounds-check everything it reads (the Draco path indexes arrays with indices from the
// file), so preflightDraco() checks those indices and decodes the Draco bitstreams once before
// tinygltf sees them, and readAccessor() checks every accessor against its buffer before reading.
#include <draco/compression/decode.h>
#include <sys/stat.h>
#include <tiny_gltf.h>

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstring>
#include <functional>
#include <nlohmann/json.hpp>

#include "canopy/atomic_file.h"
#include "canopy/errors.h"
#include "gltf_scene.h"
#include "mesh_io.h"

namespace canopy::mesh {
namespace {

using Json = nlohmann::json;

std::string oneLine(std::string s) {
  for (char& c : s)
    if (c == '\n' || c == '\r') c = ' ';
  while (!s.empty() && s.back() == ' ') s.pop_back();
  if (s.size() > 300) s = s.substr(0, 300) + "...";
  return s;
}

// ---- Preflight: the checks tinygltf 2.7 skips on its Draco path -------------------------------

// The JSON text of a .glb (its first chunk) or a .gltf; throws on a malformed GLB container.
std::string jsonText(const uint8_t* data, size_t size, bool binary, const std::string& name) {
  if (!binary) return std::string(reinterpret_cast<const char*>(data), size);
  if (size < 20) throw invalidInput(name + ": truncated GLB (" + std::to_string(size) + " bytes)");
  uint32_t magic, version, length, chunkLen, chunkType;
  std::memcpy(&magic, data, 4);
  std::memcpy(&version, data + 4, 4);
  std::memcpy(&length, data + 8, 4);
  std::memcpy(&chunkLen, data + 12, 4);
  std::memcpy(&chunkType, data + 16, 4);
  if (magic != 0x46546C67u) throw invalidInput(name + ": not a GLB file (bad magic)");
  if (version != 2) throw unsupported(name + ": GLB version " + std::to_string(version) + " (only 2)");
  if (length > size)
    throw invalidInput(name + ": truncated GLB (header says " + std::to_string(length) +
                       " bytes, file has " + std::to_string(size) + ")");
  if (chunkType != 0x4E4F534Au || uint64_t(chunkLen) + 20 > length)
    throw invalidInput(name + ": GLB JSON chunk is missing or overruns the file");
  return std::string(reinterpret_cast<const char*>(data + 20), chunkLen);
}

size_t componentCount(const std::string& type) {
  if (type == "SCALAR") return 1;
  if (type == "VEC2") return 2;
  if (type == "VEC3") return 3;
  if (type == "VEC4") return 4;
  return 0;
}

// The GLB's binary chunk (null when there is none, or for a .gltf).
struct BinChunk {
  const uint8_t* bin = nullptr;
  size_t binSize = 0;
};

// Finds the binary chunk after a GLB's JSON chunk.
BinChunk glbBinChunk(const uint8_t* data, size_t size, bool binary) {
  BinChunk c;
  if (binary) {
    uint32_t jsonLen;
    std::memcpy(&jsonLen, data + 12, 4);
    size_t at = 20 + size_t(jsonLen);
    at = (at + 3) & ~size_t(3);
    if (at + 8 <= size) {
      uint32_t len, type;
      std::memcpy(&len, data + at, 4);
      std::memcpy(&type, data + at + 4, 4);
      if (type == 0x004E4942u && at + 8 + size_t(len) <= size) {
        c.bin = data + at + 8;
        c.binSize = len;
      }
    }
  }
  return c;
}

// The top-level arrays of the glTF JSON the Draco checks read, and the binary chunk.
struct DracoContext {
  const Json& views;
  const Json& accessors;
  const Json& buffers;
  BinChunk chunk;
  const std::string& name;

  Error bad(const std::string& what) const { return invalidInput(name + ": " + what); }
  // v as an index below n; throws naming `what` otherwise.
  size_t index(const Json& v, size_t n, const std::string& what) const {
    if (!v.is_number_integer() || v.get<int64_t>() < 0 || size_t(v.get<int64_t>()) >= n)
      throw bad(what + " is out of range");
    return size_t(v.get<int64_t>());
  }
};

// Top-level array `key` of j, or an empty array.
const Json& jsonArray(const Json& j, const char* key) {
  static const Json empty = Json::array();
  auto it = j.find(key);
  return (it != j.end() && it->is_array()) ? *it : empty;
}

// Decodes a Draco primitive's bitstream in the GLB chunk and checks each attribute id against it.
void decodeDracoPrimitive(const DracoContext& x, const Json& p, const Json& ext, const Json& view, size_t v,
                          const std::string& where) {
  const uint64_t off = view.value("byteOffset", uint64_t(0));
  const uint64_t len = view.value("byteLength", uint64_t(0));
  if (off + len > x.chunk.binSize) throw x.bad(where + ": bufferView " + std::to_string(v) + " overruns the binary chunk");
  draco::DecoderBuffer db;
  db.Init(reinterpret_cast<const char*>(x.chunk.bin + off), size_t(len));
  draco::Decoder decoder;
  auto result = decoder.DecodeMeshFromBuffer(&db);
  if (!result.ok()) throw x.bad(where + ": Draco decoding failed (" + result.status().error_msg_string() + ")");
  const auto& dmesh = result.value();
  for (auto& [attr, id] : ext["attributes"].items()) {
    if (!id.is_number_integer()) throw x.bad(where + ": attribute id of " + attr + " is not an integer");
    auto it = p["attributes"].find(attr);
    if (it == p["attributes"].end()) throw x.bad(where + ": Draco attribute " + attr + " is not a primitive attribute");
    const draco::PointAttribute* pa = dmesh->GetAttributeByUniqueId(id.get<uint32_t>());
    if (!pa) throw x.bad(where + ": Draco stream lacks attribute " + attr);
    const Json& acc = x.accessors[size_t(it->get<int64_t>())];
    if (!acc.is_object() || componentCount(acc.value("type", "")) != size_t(pa->num_components()))
      throw x.bad(where + ": attribute " + attr + " component count differs from its accessor");
  }
}

// Primitive pi of mesh mi, if Draco-compressed: its indices, then its bitstream when in the GLB chunk.
void checkDracoPrimitive(const DracoContext& x, const Json& p, size_t mi, size_t pi) {
  if (!p.is_object() || !p.contains("extensions") || !p["extensions"].is_object()) return;
  auto ext = p["extensions"].find("KHR_draco_mesh_compression");
  if (ext == p["extensions"].end()) return;
  const std::string where =
      "mesh " + std::to_string(mi) + " primitive " + std::to_string(pi) + " (Draco)";
  if (!ext->is_object() || !ext->contains("bufferView") || !ext->contains("attributes") ||
      !(*ext)["attributes"].is_object() || !p.contains("attributes") ||
      !p["attributes"].is_object())
    throw x.bad(where + ": malformed KHR_draco_mesh_compression");
  const size_t v = x.index((*ext)["bufferView"], x.views.size(), where + " bufferView");
  const Json& view = x.views[v];
  if (!view.is_object() || !view.contains("buffer"))
    throw x.bad(where + ": bufferView " + std::to_string(v) + " has no buffer");
  const size_t b = x.index(view["buffer"], x.buffers.size(), where + " buffer");
  if (p.contains("indices")) x.index(p["indices"], x.accessors.size(), where + " indices accessor");
  for (auto& [attr, acc] : p["attributes"].items())
    x.index(acc, x.accessors.size(), where + " accessor of " + attr);
  // Decode when the bitstream is in the GLB chunk (buffer 0 without a uri).
  const bool inBin = x.chunk.bin && b == 0 && !x.buffers[0].contains("uri");
  if (!inBin) return;
  decodeDracoPrimitive(x, p, *ext, view, v, where);
}

// For each Draco primitive: the extension's bufferView, the primitive's accessors, and every
// attribute id named by the extension must exist, and the attribute's component count must match
// its accessor. Decodes the bitstream (cheap next to voxelising) when the GLB's binary chunk holds
// it; external buffers are checked by tinygltf's own loader.
void preflightDraco(const uint8_t* data, size_t size, bool binary, const std::string& name) {
  const std::string text = jsonText(data, size, binary, name);
  Json j = Json::parse(text, nullptr, false);
  if (j.is_discarded() || !j.is_object()) return;  // tinygltf reports the JSON error
  const BinChunk chunk = glbBinChunk(data, size, binary);  // GLB binary chunk, if any
  const Json& meshes = jsonArray(j, "meshes");
  const DracoContext x{jsonArray(j, "bufferViews"), jsonArray(j, "accessors"), jsonArray(j, "buffers"), chunk, name};
  for (size_t mi = 0; mi < meshes.size(); ++mi) {
    const Json& prims = meshes[mi].value("primitives", Json::array());
    if (!prims.is_array()) continue;
    for (size_t pi = 0; pi < prims.size(); ++pi) checkDracoPrimitive(x, prims[pi], mi, pi);
  }
}

// ---- Accessors --------------------------------------------------------------------------------

// Reads accessor `index` as `comps` doubles per element (normalised integers mapped to [0,1] or
// [-1,1]), checking every byte it touches.
std::vector<double> readAccessor(const tinygltf::Model& m, int index, size_t comps,
                                 const std::string& what, const std::string& name) {
  auto bad = [&](const std::string& why) {
    return invalidInput(name + ": " + what + " accessor " + std::to_string(index) + ": " + why);
  };
  if (index < 0 || size_t(index) >= m.accessors.size()) throw bad("index out of range");
  const tinygltf::Accessor& a = m.accessors[size_t(index)];
  if (a.sparse.isSparse) throw unsupported(name + ": sparse accessors are not supported");
  const int nc = tinygltf::GetNumComponentsInType(uint32_t(a.type));
  if (nc < 0 || size_t(nc) != comps) throw bad("has " + std::to_string(nc) + " components, expected " + std::to_string(comps));
  const int cs = tinygltf::GetComponentSizeInBytes(uint32_t(a.componentType));
  if (cs <= 0) throw bad("unknown component type");
  std::vector<double> out;
  if (a.count == 0) return out;
  if (a.bufferView < 0 || size_t(a.bufferView) >= m.bufferViews.size()) throw bad("bufferView out of range");
  const tinygltf::BufferView& v = m.bufferViews[size_t(a.bufferView)];
  if (v.buffer < 0 || size_t(v.buffer) >= m.buffers.size()) throw bad("buffer out of range");
  const std::vector<unsigned char>& buf = m.buffers[size_t(v.buffer)].data;
  const size_t elem = size_t(cs) * comps;
  const size_t stride = v.byteStride ? size_t(v.byteStride) : elem;
  if (stride < elem) throw bad("byteStride smaller than an element");
  const uint64_t need = uint64_t(a.byteOffset) + uint64_t(stride) * (a.count - 1) + elem;
  if (uint64_t(v.byteOffset) + uint64_t(v.byteLength) > buf.size() || need > v.byteLength)
    throw bad("overruns its buffer (truncated or missing data)");
  out.resize(a.count * comps);
  const unsigned char* base = buf.data() + v.byteOffset + a.byteOffset;
  for (size_t i = 0; i < a.count; ++i) {
    const unsigned char* e = base + i * stride;
    for (size_t c = 0; c < comps; ++c) {
      const unsigned char* s = e + c * size_t(cs);
      double x = 0;
      switch (a.componentType) {
        case TINYGLTF_COMPONENT_TYPE_FLOAT: { float f; std::memcpy(&f, s, 4); x = f; break; }
        case TINYGLTF_COMPONENT_TYPE_DOUBLE: { double d; std::memcpy(&d, s, 8); x = d; break; }
        case TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE: x = *s; if (a.normalized) x /= 255.0; break;
        case TINYGLTF_COMPONENT_TYPE_BYTE: { int8_t t; std::memcpy(&t, s, 1); x = a.normalized ? std::max(-1.0, t / 127.0) : t; break; }
        case TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT: { uint16_t t; std::memcpy(&t, s, 2); x = a.normalized ? t / 65535.0 : t; break; }
        case TINYGLTF_COMPONENT_TYPE_SHORT: { int16_t t; std::memcpy(&t, s, 2); x = a.normalized ? std::max(-1.0, t / 32767.0) : t; break; }
        case TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT: { uint32_t t; std::memcpy(&t, s, 4); x = t; break; }
        case TINYGLTF_COMPONENT_TYPE_INT: { int32_t t; std::memcpy(&t, s, 4); x = t; break; }
        default: throw bad("unknown component type");
      }
      out[i * comps + c] = x;
    }
  }
  return out;
}

// ---- Transforms ---------------------------------------------------------------------------------

Mat4 identity() { return {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1}; }

Mat4 mul(const Mat4& a, const Mat4& b) {
  Mat4 r{};
  for (int i = 0; i < 4; ++i)
    for (int j = 0; j < 4; ++j) {
      double s = 0;
      for (int k = 0; k < 4; ++k) s += a[i * 4 + k] * b[k * 4 + j];
      r[i * 4 + j] = s;
    }
  return r;
}

// A node's local matrix: `matrix` (column-major in glTF) or T * R * S.
Mat4 localMatrix(const tinygltf::Node& n) {
  if (n.matrix.size() == 16) {
    Mat4 r;
    for (int i = 0; i < 4; ++i)
      for (int j = 0; j < 4; ++j) r[i * 4 + j] = n.matrix[size_t(j * 4 + i)];
    return r;
  }
  Mat4 t = identity(), r = identity(), s = identity();
  if (n.translation.size() == 3) { t[3] = n.translation[0]; t[7] = n.translation[1]; t[11] = n.translation[2]; }
  if (n.rotation.size() == 4) {
    double x = n.rotation[0], y = n.rotation[1], z = n.rotation[2], w = n.rotation[3];
    const double len = std::sqrt(x * x + y * y + z * z + w * w);
    if (len > 0) { x /= len; y /= len; z /= len; w /= len; }
    r = {1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w), 0,
         2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w), 0,
         2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y), 0,
         0, 0, 0, 1};
  }
  if (n.scale.size() == 3) { s[0] = n.scale[0]; s[5] = n.scale[1]; s[10] = n.scale[2]; }
  return mul(t, mul(r, s));
}

Vec3 transformPoint(const Mat4& m, const Vec3& p) {
  return {m[0] * p[0] + m[1] * p[1] + m[2] * p[2] + m[3],
          m[4] * p[0] + m[5] * p[1] + m[6] * p[2] + m[7],
          m[8] * p[0] + m[9] * p[1] + m[10] * p[2] + m[11]};
}

// Instances of the default scene (every node that references a mesh, with its world matrix).
std::vector<Instance> collectInstances(const tinygltf::Model& m, const std::string& name) {
  std::vector<int> roots;
  if (!m.scenes.empty()) {
    const int s = m.defaultScene >= 0 && size_t(m.defaultScene) < m.scenes.size() ? m.defaultScene : 0;
    roots = m.scenes[size_t(s)].nodes;
  } else {
    // No scene: every node that is no other node's child is a root.
    std::vector<bool> isChild(m.nodes.size(), false);
    for (auto& n : m.nodes)
      for (int c : n.children)
        if (c >= 0 && size_t(c) < m.nodes.size()) isChild[size_t(c)] = true;
    for (size_t i = 0; i < m.nodes.size(); ++i)
      if (!isChild[i]) roots.push_back(int(i));
  }
  std::vector<Instance> out;
  std::vector<int> onPath(m.nodes.size(), 0);
  std::function<void(int, const Mat4&)> visit = [&](int ni, const Mat4& parent) {
    if (ni < 0 || size_t(ni) >= m.nodes.size())
      throw invalidInput(name + ": node index " + std::to_string(ni) + " out of range");
    if (onPath[size_t(ni)]) throw invalidInput(name + ": node hierarchy has a cycle at node " + std::to_string(ni));
    onPath[size_t(ni)] = 1;
    const tinygltf::Node& n = m.nodes[size_t(ni)];
    const Mat4 world = mul(parent, localMatrix(n));
    if (n.mesh >= 0) {
      if (size_t(n.mesh) >= m.meshes.size())
        throw invalidInput(name + ": node " + std::to_string(ni) + " references missing mesh " + std::to_string(n.mesh));
      out.push_back({n.name.empty() ? "node" + std::to_string(ni) : n.name, n.mesh, world});
    }
    for (int c : n.children) visit(c, world);
    onPath[size_t(ni)] = 0;
  };
  for (int r : roots) visit(r, identity());
  return out;
}

// ---- Materials and textures ---------------------------------------------------------------------

void loadMaterials(const tinygltf::Model& m, Mesh& out, const std::string& name) {
  std::vector<int> textureSlot(m.textures.size(), -1);  // glTF texture -> Mesh::textures index
  for (const tinygltf::Material& gm : m.materials) {
    Material mat;
    mat.name = gm.name;
    const auto& pbr = gm.pbrMetallicRoughness;
    for (int c = 0; c < 4 && c < int(pbr.baseColorFactor.size()); ++c)
      mat.baseColorFactor[size_t(c)] = float(pbr.baseColorFactor[size_t(c)]);
    mat.alphaMode = gm.alphaMode == "MASK" ? AlphaMode::Mask
                    : gm.alphaMode == "BLEND" ? AlphaMode::Blend : AlphaMode::Opaque;
    mat.alphaCutoff = float(gm.alphaCutoff);
    const int ti = pbr.baseColorTexture.index;
    if (ti >= 0) {
      if (size_t(ti) >= m.textures.size())
        throw invalidInput(name + ": material '" + gm.name + "' references missing texture " + std::to_string(ti));
      if (textureSlot[size_t(ti)] < 0) {
        const tinygltf::Texture& gt = m.textures[size_t(ti)];
        if (gt.source < 0 || size_t(gt.source) >= m.images.size())
          throw invalidInput(name + ": texture " + std::to_string(ti) + " has no image");
        const tinygltf::Image& img = m.images[size_t(gt.source)];
        if (img.width <= 0 || img.height <= 0 || img.image.empty())
          throw invalidInput(name + ": image " + std::to_string(gt.source) +
                             (img.uri.empty() ? "" : " ('" + img.uri + "')") + " could not be decoded");
        Texture t;
        t.width = img.width;
        t.height = img.height;
        const size_t px = size_t(img.width) * size_t(img.height);
        const size_t comps = size_t(std::max(1, img.component));
        const size_t bytes = size_t(std::max(8, img.bits)) / 8;
        if (img.image.size() < px * comps * bytes)
          throw invalidInput(name + ": image " + std::to_string(gt.source) + " has too few bytes");
        t.rgba.resize(px * 4);
        for (size_t i = 0; i < px; ++i)
          for (size_t c = 0; c < 4; ++c) {
            // Grey (+alpha) images replicate grey into RGB; a missing alpha is opaque.
            const int src = comps >= 3 ? (c < comps ? int(c) : -1)
                                       : (c < 3 ? 0 : (comps == 2 ? 1 : -1));
            uint8_t v = 255;
            if (src >= 0) {
              const size_t at = (i * comps + size_t(src)) * bytes;
              if (bytes == 2) {
                uint16_t w;
                std::memcpy(&w, &img.image[at], 2);
                v = uint8_t(w >> 8);
              } else {
                v = img.image[at];
              }
            }
            t.rgba[i * 4 + c] = v;
          }
        if (gt.sampler >= 0 && size_t(gt.sampler) < m.samplers.size()) {
          const auto& s = m.samplers[size_t(gt.sampler)];
          t.wrapS = s.wrapS;
          t.wrapT = s.wrapT;
          t.nearest = s.magFilter == TINYGLTF_TEXTURE_FILTER_NEAREST;
        }
        textureSlot[size_t(ti)] = int(out.textures.size());
        out.textures.push_back(std::move(t));
      }
      mat.baseColorTexture = textureSlot[size_t(ti)];
      mat.texCoord = pbr.baseColorTexture.texCoord;
    }
    out.materials.push_back(std::move(mat));
  }
  // Primitives without a material use glTF's default material (index = materials.size()).
  Material def;
  def.name = "default";
  out.materials.push_back(def);
}

// ---- Geometry -----------------------------------------------------------------------------------

void appendPrimitive(const tinygltf::Model& m, const tinygltf::Primitive& p, const Mat4& world,
                     int defaultMaterial, Mesh& out, const std::string& name) {
  if (p.mode != TINYGLTF_MODE_TRIANGLES && p.mode != TINYGLTF_MODE_TRIANGLE_STRIP &&
      p.mode != TINYGLTF_MODE_TRIANGLE_FAN) {
    ++out.droppedNonTriangles;
    return;
  }
  auto pos = p.attributes.find("POSITION");
  if (pos == p.attributes.end()) throw invalidInput(name + ": a primitive has no POSITION");
  const std::vector<double> P = readAccessor(m, pos->second, 3, "POSITION", name);
  const size_t nv = P.size() / 3;
  int mi = p.material;
  if (mi < 0) mi = defaultMaterial;
  if (size_t(mi) > size_t(defaultMaterial))
    throw invalidInput(name + ": primitive references missing material " + std::to_string(mi));
  const Material& mat = out.materials[size_t(mi)];
  std::vector<double> UV;
  if (mat.baseColorTexture >= 0) {
    auto uv = p.attributes.find("TEXCOORD_" + std::to_string(mat.texCoord));
    if (uv != p.attributes.end()) {
      UV = readAccessor(m, uv->second, 2, "TEXCOORD", name);
      if (UV.size() / 2 != nv) throw invalidInput(name + ": TEXCOORD count differs from POSITION count");
    }
  }
  std::vector<uint32_t> idx;
  if (p.indices >= 0) {
    const std::vector<double> I = readAccessor(m, p.indices, 1, "indices", name);
    idx.reserve(I.size());
    for (double d : I) {
      if (d < 0 || d >= double(nv)) throw invalidInput(name + ": vertex index " + std::to_string(int64_t(d)) + " out of range (" + std::to_string(nv) + " vertices)");
      idx.push_back(uint32_t(d));
    }
  } else {
    idx.resize(nv);
    for (size_t i = 0; i < nv; ++i) idx[i] = uint32_t(i);
  }
  auto emit = [&](uint32_t a, uint32_t b, uint32_t c) {
    Triangle t;
    const uint32_t v[3] = {a, b, c};
    for (int k = 0; k < 3; ++k) {
      t.p[size_t(k)] = transformPoint(world, {P[v[k] * 3], P[v[k] * 3 + 1], P[v[k] * 3 + 2]});
      if (!UV.empty()) t.uv[size_t(k)] = {float(UV[v[k] * 2]), float(UV[v[k] * 2 + 1])};
    }
    t.material = mi;
    out.triangles.push_back(t);
  };
  if (p.mode == TINYGLTF_MODE_TRIANGLES) {
    for (size_t i = 0; i + 2 < idx.size(); i += 3) emit(idx[i], idx[i + 1], idx[i + 2]);
  } else if (p.mode == TINYGLTF_MODE_TRIANGLE_STRIP) {
    for (size_t i = 0; i + 2 < idx.size(); ++i)
      (i & 1) ? emit(idx[i + 1], idx[i], idx[i + 2]) : emit(idx[i], idx[i + 1], idx[i + 2]);
  } else {
    for (size_t i = 1; i + 1 < idx.size(); ++i) emit(idx[0], idx[i], idx[i + 1]);
  }
}

tinygltf::Model parseModel(const uint8_t* data, size_t size, bool binary, const std::string& baseDir,
                           const std::string& name) {
  if (size == 0) throw invalidInput(name + ": empty file");
  if (size > 0xFFFFFFFFu) throw unsupported(name + ": glTF files over 4 GiB are not supported");
  preflightDraco(data, size, binary, name);
  tinygltf::TinyGLTF loader;
  // External buffers and images are inputs of the run too: an output path naming one of them is
  // refused like one naming the glTF itself (canopy/atomic_file.h). Only regular files are read: a
  // URI naming a FIFO or a device would block or never end (tinygltf's own FileExists opens the
  // file, which blocks on a FIFO, so existence is a stat).
  loader.SetFsCallbacks({[](const std::string& path, void*) {
                           struct stat st;
                           return stat(path.c_str(), &st) == 0;
                         },
                         &tinygltf::ExpandFilePath,
                         [](std::vector<unsigned char>* out, std::string* err, const std::string& path, void* user) {
                           struct stat st;
                           if (stat(path.c_str(), &st) == 0 && !S_ISREG(st.st_mode)) {
                             if (err) *err += "not a regular file";  // tinygltf prefixes the path
                             return false;
                           }
                           noteInput(path);
                           return tinygltf::ReadWholeFile(out, err, path, user);
                         },
                         &tinygltf::WriteWholeFile, nullptr});
  tinygltf::Model model;
  std::string err, warn;
  const bool ok = binary
      ? loader.LoadBinaryFromMemory(&model, &err, &warn, data, unsigned(size), baseDir)
      : loader.LoadASCIIFromString(&model, &err, &warn, reinterpret_cast<const char*>(data),
                                   unsigned(size), baseDir);
  if (!ok || !err.empty()) {
    const std::string e = oneLine(err.empty() ? warn : err);
    // A missing or unreadable external buffer or image (tinygltf: "File not found", "File read
    // error", "Failed to load external") is an I/O problem; anything else is malformed content.
    const bool io = e.find("ile not found") != std::string::npos ||
                    e.find("File read error") != std::string::npos ||
                    e.find("Failed to load external") != std::string::npos;
    throw Error(io ? ExitCode::Io : ExitCode::InvalidInput,
                name + ": invalid glTF (" + (e.empty() ? "unknown error" : e) + ")");
  }
  // A required extension Canopy does not implement would silently change the geometry or the
  // texture lookup: refuse it. (Material extensions only change shading, which Canopy ignores.)
  for (const std::string& ext : model.extensionsRequired)
    if (ext != "KHR_draco_mesh_compression" && ext != "KHR_mesh_quantization" &&
        ext.rfind("KHR_materials_", 0) != 0)
      throw unsupported(name + ": requires glTF extension " + ext + ", which Canopy does not support");
  // tinygltf only warns about an external image it cannot find; Canopy needs every image.
  if (warn.find("ile not found") != std::string::npos)
    throw ioError(name + ": a referenced file is missing (" + oneLine(warn) + ")");
  return model;
}

Mesh buildMesh(const tinygltf::Model& model, const std::string& name, const LoadOptions& o) {
  Mesh out;
  loadMaterials(model, out, name);
  const int defaultMaterial = int(out.materials.size()) - 1;
  if (o.meshIndex >= 0) {
    if (size_t(o.meshIndex) >= model.meshes.size())
      throw usageError(name + ": --mesh " + std::to_string(o.meshIndex) + " but the file has " +
                       std::to_string(model.meshes.size()) + " meshes");
    for (const auto& p : model.meshes[size_t(o.meshIndex)].primitives)
      appendPrimitive(model, p, identity(), defaultMaterial, out, name);
  } else {
    const std::vector<Instance> instances = collectInstances(model, name);
    checkInstanceMatrices(instances, name);
    for (const Instance& inst : instances)
      for (const auto& p : model.meshes[size_t(inst.mesh)].primitives)
        appendPrimitive(model, p, inst.matrix, defaultMaterial, out, name);
  }
  return out;
}

std::string dirOf(const std::string& path) {
  auto s = path.find_last_of('/');
  return s == std::string::npos ? "." : (s == 0 ? "/" : path.substr(0, s));
}

}  // namespace

Mesh loadGltfFromMemory(const uint8_t* data, size_t size, bool binary, const std::string& baseDir,
                        const std::string& name, const LoadOptions& options) {
  return buildMesh(parseModel(data, size, binary, baseDir, name), name, options);
}

// Here rather than with the other loaders: the glTF reader (canopy_gltf) stands alone.
std::string extensionOf(const std::string& path) {
  const auto slash = path.find_last_of('/');
  const auto dot = path.find_last_of('.');
  if (dot == std::string::npos || (slash != std::string::npos && dot < slash)) return "";
  std::string e = path.substr(dot + 1);
  std::transform(e.begin(), e.end(), e.begin(), [](unsigned char c) { return char(std::tolower(c)); });
  return e;
}

Mesh loadGltfFile(const std::string& path, const LoadOptions& options) {
  const std::vector<unsigned char> bytes = readFile(path);
  const bool binary = extensionOf(path) == "glb";
  return loadGltfFromMemory(bytes.data(), bytes.size(), binary, dirOf(path), path, options);
}

SceneInfo listGltfScene(const std::string& path) {
  const std::string ext = extensionOf(path);
  if (ext != "glb" && ext != "gltf") throw unsupported(path + ": scene listing needs a .glb or .gltf file");
  const std::vector<unsigned char> bytes = readFile(path);
  const tinygltf::Model model = parseModel(bytes.data(), bytes.size(), ext == "glb", dirOf(path), path);
  SceneInfo info;
  Mesh dummy;
  loadMaterials(model, dummy, path);
  const int defaultMaterial = int(dummy.materials.size()) - 1;
  for (size_t i = 0; i < model.meshes.size(); ++i) {
    Mesh one;
    one.materials = dummy.materials;
    for (const auto& p : model.meshes[i].primitives)
      appendPrimitive(model, p, identity(), defaultMaterial, one, path);
    info.meshes.push_back({model.meshes[i].name.empty() ? "mesh" + std::to_string(i) : model.meshes[i].name,
                           one.triangles.size()});
  }
  info.instances = collectInstances(model, path);
  return info;
}

}  // namespace canopy::mesh
