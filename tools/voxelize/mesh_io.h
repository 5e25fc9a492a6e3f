// mesh_io.h: loads plant meshes into one flat, world-space triangle soup with materials.
//
// Formats: glTF 2.0 (.gltf/.glb, KHR_draco_mesh_compression, embedded and external images) via
// tinygltf compiled with Draco (gltf_loader.cpp); OBJ and STL via OpenMesh (openmesh_loader.cpp);
// PLY and ASCII OFF by Canopy's own readers (ply_loader.cpp, off_loader.cpp: OpenMesh's hang on
// truncated PLY, and run out of memory or drop data on bad OFF).
// Every loader validates its input and throws canopy::Error naming the file; nothing here trusts
// the file. Positions are doubles in the file's units (metres for glTF), glTF node transforms
// already applied. Reusable by other tools: gltf_scene.h turns listGltfScene() into the Canopy
// scene (models + instances) that voxelize --instances writes and octreepack --scene packs.
#pragma once
#include <array>
#include <cstdint>
#include <string>
#include <vector>

#include "canopy/errors.h"

namespace canopy::mesh {

using Vec3 = std::array<double, 3>;
using Mat4 = std::array<double, 16>;  // row-major, column vectors: p' = M p

// RGBA8 image, rows top to bottom (glTF's uv (0,0) is the top-left corner).
struct Texture {
  int width = 0, height = 0;
  std::vector<uint8_t> rgba;
  int wrapS = 10497, wrapT = 10497;  // glTF: 10497 REPEAT, 33071 CLAMP_TO_EDGE, 33648 MIRRORED
  bool nearest = false;              // magFilter NEAREST; otherwise bilinear
};

enum class AlphaMode { Opaque, Mask, Blend };

struct Material {
  std::string name;
  std::array<float, 4> baseColorFactor{1, 1, 1, 1};  // linear RGBA
  int baseColorTexture = -1;                          // index into Mesh::textures, -1 = none
  int texCoord = 0;                                   // which TEXCOORD_n the texture uses
  AlphaMode alphaMode = AlphaMode::Opaque;
  float alphaCutoff = 0.5f;
  bool hasColor = true;  // false: the file carries no colour (a plain OBJ/STL); use defaults
};

struct Triangle {
  std::array<Vec3, 3> p;                    // world (model) space
  std::array<std::array<float, 2>, 3> uv{};  // the material's texCoord set (0 where absent)
  int32_t material = 0;                      // index into Mesh::materials
  std::array<float, 3> color{1, 1, 1};       // linear RGB from face/vertex colours (OpenMesh formats)
};

struct Mesh {
  std::vector<Triangle> triangles;
  std::vector<Material> materials;  // never empty after loading
  std::vector<Texture> textures;
  size_t droppedNonTriangles = 0;   // points/lines primitives skipped (glTF)
  bool hasTriangleColors = false;   // Triangle::color carries the file's colours
};

// One glTF mesh used by one node: its world matrix (the product of the node chain).
struct Instance {
  std::string nodeName;
  int mesh = 0;
  Mat4 matrix{};  // model -> world, row-major
};

struct MeshInfo {
  std::string name;
  size_t triangles = 0;
};

struct SceneInfo {
  std::vector<MeshInfo> meshes;      // glTF meshes
  std::vector<Instance> instances;   // one per node (of the default scene) that references a mesh
};

struct LoadOptions {
  // glTF only: -1 = the whole default scene with node transforms (all instances in one soup);
  // N >= 0 = glTF mesh N alone, in its own model space (identity transform).
  int meshIndex = -1;
};

// Loads any supported format (chosen by extension, case-insensitive). Throws canopy::Error:
// Io (missing, directory, unreadable), InvalidInput (corrupt, truncated, NaN/inf coordinates,
// bad indices, missing buffers), Unsupported (unknown extension, unsupported glTF feature).
Mesh loadMesh(const std::string& path, const LoadOptions& options = {});

// glTF only: the meshes and the instances (node world matrices) of the default scene.
SceneInfo listGltfScene(const std::string& path);

// Loaders by format (exposed for fuzzers and tests). baseDir resolves external glTF URIs;
// `name` is what error messages call the input.
Mesh loadGltfFromMemory(const uint8_t* data, size_t size, bool binary, const std::string& baseDir,
                        const std::string& name, const LoadOptions& options = {});
Mesh loadGltfFile(const std::string& path, const LoadOptions& options = {});
// OBJ, STL (and PLY and OFF, which it hands to loadPly and loadOff).
Mesh loadWithOpenMesh(const std::string& path);
// ASCII OFF ([ST][C][N]OFF): every count, coordinate, index and colour is checked.
Mesh loadOff(const std::string& path);
Mesh loadOffFromMemory(const uint8_t* data, size_t size, const std::string& name);
// PLY (ascii, binary little/big endian): every header field, length and index is checked.
Mesh loadPly(const std::string& path);
Mesh loadPlyFromMemory(const uint8_t* data, size_t size, const std::string& name);

// Throws invalidInput naming `name` if any coordinate is NaN or infinite.
void requireFinite(const Mesh& mesh, const std::string& name);
// The error requireFinite throws for triangle `index` (0-based), for loaders that find it first.
Error nonFiniteTriangle(const std::string& name, size_t index);

// Lower-case extension without the dot ("glb"), or "".
std::string extensionOf(const std::string& path);

}  // namespace canopy::mesh
