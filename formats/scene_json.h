// scene_json.h: the scene instance list (`canopy_scene` 1, docs/scene-json.md): one reader and one
// writer for every tool. canopy-voxelize --instances writes it from a glTF scene; canopy-lbsolve
// --scene and canopy-octreepack --scene read it.
//
//   { "canopy_scene": 1,
//     "source": "grove.glb xxh64:<hex>",                    (optional: the glTF it was listed from)
//     "models": [ { "name": "oak", "density": "oak.density.vdb",
//                   "light": "oak.light.chaar",              (optional)
//                   "mesh": 0 } ],                           (optional: the glTF mesh index)
//     "instances": [ { "model": 0, "node": "Oak_1",          (node optional)
//                      "matrix": [16 numbers, row-major 4x4 model -> world, last row 0,0,0,1] } ] }
//
// Invariants checked by checkScene (which the reader calls): at least one model and one instance,
// every instance names an existing model, every matrix is finite, affine (last row 0,0,0,1) and
// invertible. The reader also requires a non-empty density path per model. Every violation is a canopy::Error naming the file and
// the offending entry (InvalidInput; Unsupported for another format version).
#pragma once
#include <array>
#include <cstdint>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

namespace canopy {

constexpr int kSceneJsonVersion = 1;

// The farthest world coordinate a scene may reach (metres): canopy-play marches rays in single
// precision, whose positions lose the scene beyond (squares of coordinates near 1e19 overflow).
// checkScene bounds every matrix entry by it; canopy-play every instance's world bounds.
constexpr double kMaxWorldCoordinate = 1e9;

struct SceneModel {
  std::string name;     // label ("model<i>" where the file gives none)
  std::string density;  // the model's lattice (canopy-voxelize), model space
  std::string light;    // its lighting (.chaar or lbsolve .vdb); "" = none
  int mesh = -1;        // the glTF mesh it was voxelised from; -1 = unknown
};

struct SceneInstance {
  uint32_t model = 0;
  std::string node;               // the glTF node it came from; "" = none
  std::array<double, 16> matrix;  // model -> world, row-major, column vectors (p' = M p)
};

struct Scene {
  std::string source;  // where the instances were computed from ("<file name> xxh64:<hex>"), or ""
  std::vector<SceneModel> models;
  std::vector<SceneInstance> instances;
};

// Checks the invariants above; `name` (the file) prefixes every error message.
void checkScene(const Scene& scene, const std::string& name);

// A parsed document -> Scene (checked). Relative model paths get `baseDir` prefixed (pass the
// file's folder with its trailing '/', or "" to keep them as written).
Scene sceneFromJson(const nlohmann::json& doc, const std::string& name, const std::string& baseDir = "");

// Reads and checks a scene file; model paths are resolved against the file's folder.
Scene readSceneJson(const std::string& path);

// Scene -> document (paths as stored), and the atomic file writer (two-space indent, newline).
nlohmann::json sceneToJson(const Scene& scene);
void writeSceneJson(const std::string& path, const Scene& scene);

}  // namespace canopy
