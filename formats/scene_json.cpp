// scene_json.cpp: see scene_json.h.
#include "formats/scene_json.h"

#include <cmath>
#include <cstdint>
#include <functional>

#include "canopy/atomic_file.h"
#include "canopy/errors.h"
#include "canopy/json_file.h"

namespace canopy {
namespace {

std::string folderOf(const std::string& path) {
  const auto s = path.find_last_of('/');
  return s == std::string::npos ? std::string() : path.substr(0, s + 1);
}

double det3(const std::array<double, 16>& m) {
  return m[0] * (m[5] * m[10] - m[6] * m[9]) - m[1] * (m[4] * m[10] - m[6] * m[8]) +
         m[2] * (m[4] * m[9] - m[5] * m[8]);
}

SceneModel modelFromJson(const nlohmann::json& m, size_t i, const std::string& baseDir,
                         const std::function<Error(const std::string&)>& fail) {
  const std::string at = "models[" + std::to_string(i) + "]";
  if (!m.is_object() || !m.contains("density") || !m["density"].is_string() ||
      m["density"].get_ref<const std::string&>().empty())
    throw fail(at + " needs a 'density' path");
  auto resolve = [&](const std::string& p) { return p[0] == '/' ? p : baseDir + p; };
  SceneModel model;
  model.name = "model" + std::to_string(i);
  if (m.contains("name")) {
    if (!m["name"].is_string()) throw fail(at + ".name must be a string");
    model.name = m["name"].get<std::string>();
  }
  model.density = resolve(m["density"].get<std::string>());
  if (m.contains("light")) {
    if (!m["light"].is_string() || m["light"].get_ref<const std::string&>().empty())
      throw fail(at + ".light must be a non-empty path");
    model.light = resolve(m["light"].get<std::string>());
  }
  if (m.contains("mesh")) {
    if (!m["mesh"].is_number_integer() || m["mesh"].get<int64_t>() < 0 || m["mesh"].get<int64_t>() > INT32_MAX)
      throw fail(at + ".mesh must be a non-negative integer");
    model.mesh = int(m["mesh"].get<int64_t>());
  }
  return model;
}

SceneInstance instanceFromJson(const nlohmann::json& in, size_t i, size_t modelCount,
                               const std::function<Error(const std::string&)>& fail) {
  const std::string at = "instances[" + std::to_string(i) + "]";
  if (!in.is_object() || !in.contains("model") || !in["model"].is_number_integer())
    throw fail(at + " needs an integer 'model'");
  const bool inRange = in["model"].is_number_unsigned() ? in["model"].get<uint64_t>() < modelCount
                                                        : in["model"].get<int64_t>() >= 0 && uint64_t(in["model"].get<int64_t>()) < modelCount;
  if (!inRange)
    throw fail(at + ".model " + in["model"].dump() + " out of range (" + std::to_string(modelCount) + " models)");
  if (!in.contains("matrix") || !in["matrix"].is_array() || in["matrix"].size() != 16)
    throw fail(at + ".matrix must be 16 numbers (row-major 4x4)");
  SceneInstance inst;
  inst.model = uint32_t(in["model"].get<uint64_t>());
  for (size_t k = 0; k < 16; ++k) {
    if (!in["matrix"][k].is_number()) throw fail(at + ".matrix must be 16 numbers (row-major 4x4)");
    inst.matrix[k] = in["matrix"][k].get<double>();
  }
  if (in.contains("node")) {
    if (!in["node"].is_string()) throw fail(at + ".node must be a string");
    inst.node = in["node"].get<std::string>();
  }
  return inst;
}

}  // namespace

void checkScene(const Scene& s, const std::string& name) {
  auto fail = [&](const std::string& what) { return invalidInput(name + ": " + what); };
  if (s.models.empty()) throw fail("the scene has no models");
  if (s.instances.empty()) throw fail("the scene has no instances");
  for (size_t i = 0; i < s.instances.size(); ++i) {
    const SceneInstance& in = s.instances[i];
    const std::string at = "instances[" + std::to_string(i) + "]";
    if (in.model >= s.models.size())
      throw fail(at + ".model " + std::to_string(in.model) + " out of range (" + std::to_string(s.models.size()) + " models)");
    for (double v : in.matrix) {
      if (!std::isfinite(v)) throw fail(at + ".matrix is not finite");
      if (std::abs(v) > kMaxWorldCoordinate) throw fail(at + ".matrix has an entry beyond 1e9 in magnitude");
    }
    const auto& m = in.matrix;
    if (std::abs(m[12]) > 1e-6 || std::abs(m[13]) > 1e-6 || std::abs(m[14]) > 1e-6 || std::abs(m[15] - 1) > 1e-6)
      throw fail(at + ".matrix last row must be 0,0,0,1");
    if (!(std::abs(det3(m)) >= 1e-12)) throw fail(at + ".matrix is singular");
  }
}

Scene sceneFromJson(const nlohmann::json& j, const std::string& name, const std::string& baseDir) {
  const std::function<Error(const std::string&)> fail = [&](const std::string& what) { return invalidInput(name + ": " + what); };
  if (!j.is_object() || !j.contains("canopy_scene") || !j["canopy_scene"].is_number_integer())
    throw fail("not a Canopy scene (no integer 'canopy_scene')");
  const nlohmann::json& version = j["canopy_scene"];
  if (version.is_number_unsigned() ? version.get<uint64_t>() != uint64_t(kSceneJsonVersion)
                                   : version.get<int64_t>() != kSceneJsonVersion)
    throw unsupported(name + ": scene format version " + j["canopy_scene"].dump() + " is not supported (" +
                      std::to_string(kSceneJsonVersion) + ")");
  if (!j.contains("models") || !j["models"].is_array() || j["models"].empty()) throw fail("'models' must be a non-empty array");
  if (!j.contains("instances") || !j["instances"].is_array() || j["instances"].empty())
    throw fail("'instances' must be a non-empty array");
  Scene s;
  if (j.contains("source")) {
    if (!j["source"].is_string()) throw fail("'source' must be a string");
    s.source = j["source"].get<std::string>();
  }
  for (size_t i = 0; i < j["models"].size(); ++i) s.models.push_back(modelFromJson(j["models"][i], i, baseDir, fail));
  for (size_t i = 0; i < j["instances"].size(); ++i)
    s.instances.push_back(instanceFromJson(j["instances"][i], i, s.models.size(), fail));
  checkScene(s, name);
  return s;
}

Scene readSceneJson(const std::string& path) { return sceneFromJson(readJsonFile(path), path, folderOf(path)); }

nlohmann::json sceneToJson(const Scene& s) {
  nlohmann::json models = nlohmann::json::array();
  for (const SceneModel& m : s.models) {
    nlohmann::json jm = {{"name", m.name}};
    if (m.mesh >= 0) jm["mesh"] = m.mesh;
    jm["density"] = m.density;
    if (!m.light.empty()) jm["light"] = m.light;
    models.push_back(jm);
  }
  nlohmann::json instances = nlohmann::json::array();
  for (const SceneInstance& in : s.instances) {
    nlohmann::json ji = {{"model", in.model}};
    if (!in.node.empty()) ji["node"] = in.node;
    ji["matrix"] = in.matrix;
    instances.push_back(ji);
  }
  nlohmann::json doc = {{"canopy_scene", kSceneJsonVersion}};
  if (!s.source.empty()) doc["source"] = s.source;
  doc["models"] = models;
  doc["instances"] = instances;
  return doc;
}

void writeSceneJson(const std::string& path, const Scene& scene) { writeFileAtomic(path, sceneToJson(scene).dump(2) + "\n"); }

}  // namespace canopy
