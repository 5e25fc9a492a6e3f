// gltf_scene.cpp: see gltf_scene.h.
#include "gltf_scene.h"

#include <cctype>
#include <map>

#include "canopy/errors.h"
#include "canopy/hash.h"
#include "mesh_io.h"

namespace canopy::mesh {
namespace {

std::string stemOf(const std::string& p) {
  const auto s = p.find_last_of('/');
  const std::string b = s == std::string::npos ? p : p.substr(s + 1);
  const auto d = b.find_last_of('.');
  return d == std::string::npos || d == 0 ? b : b.substr(0, d);
}

std::string sanitize(const std::string& s) {
  std::string r;
  for (char c : s) r += (std::isalnum(static_cast<unsigned char>(c)) || c == '-' || c == '_') ? c : '_';
  return r.empty() ? "mesh" : r;
}

std::string replaceAll(std::string s, const std::string& from, const std::string& to) {
  for (size_t at = s.find(from); at != std::string::npos; at = s.find(from, at + to.size()))
    s.replace(at, from.size(), to);
  return s;
}

}  // namespace

Scene sceneFromGltf(const std::string& path) {
  const SceneInfo info = listGltfScene(path);
  if (info.instances.empty()) throw invalidInput(path + ": the scene has no node with a mesh");
  Scene scene;
  scene.source = describeSource(path);
  std::map<int, uint32_t> modelOf;  // glTF mesh -> model, ascending mesh index
  for (const Instance& inst : info.instances) modelOf[inst.mesh] = 0;
  for (auto& [mesh, model] : modelOf) {
    model = uint32_t(scene.models.size());
    SceneModel m;
    m.name = info.meshes[size_t(mesh)].name;
    m.mesh = mesh;
    scene.models.push_back(m);
  }
  for (const Instance& inst : info.instances) {
    SceneInstance si;
    si.model = modelOf.at(inst.mesh);
    si.node = inst.nodeName;
    si.matrix = inst.matrix;
    scene.instances.push_back(si);
  }
  checkScene(scene, path);
  return scene;
}

void checkInstanceMatrices(const std::vector<Instance>& instances, const std::string& path) {
  if (instances.empty()) return;
  Scene scene;
  scene.models.resize(1);
  for (const Instance& inst : instances) {
    SceneInstance si;
    si.matrix = inst.matrix;
    scene.instances.push_back(si);
  }
  checkScene(scene, path);
}

void applyModelPattern(Scene& scene, const std::string& gltfPath, const std::string& pattern) {
  for (SceneModel& m : scene.models) {
    std::string p = replaceAll(pattern, "{stem}", stemOf(gltfPath));
    p = replaceAll(p, "{N}", std::to_string(m.mesh));
    m.density = replaceAll(p, "{name}", sanitize(m.name));
  }
}

}  // namespace canopy::mesh
