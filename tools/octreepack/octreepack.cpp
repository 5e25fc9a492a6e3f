// octreepack.cpp: see octreepack.h.
#include "tools/octreepack/octreepack.h"

#include <cctype>
#include <chrono>
#include <cstring>
#include <map>
#include <sstream>

#include "canopy/atomic_file.h"
#include "canopy/cli.h"
#include "canopy/errors.h"
#include "formats/canopy_write.h"
#include "formats/density_lattice.h"
#include "formats/scene_json.h"
#include "gltf_scene.h"
#include "tools/octreepack/inputs.h"
#include "tools/octreepack/octree_build.h"

namespace canopy::octreepack {
namespace {

bool endsWith(const std::string& s, const std::string& suf) {
  return s.size() >= suf.size() && s.compare(s.size() - suf.size(), suf.size(), suf) == 0;
}

std::string stemOf(const std::string& path) {
  std::string base = path.substr(path.find_last_of('/') == std::string::npos ? 0 : path.find_last_of('/') + 1);
  for (const char* suf : {".density.vdb", ".detail.vdb", ".vdb"})
    if (endsWith(base, suf)) return base.substr(0, base.size() - std::strlen(suf));
  return base;
}

bool isGltf(std::string path) {
  for (char& c : path) c = char(std::tolower(static_cast<unsigned char>(c)));
  return endsWith(path, ".glb") || endsWith(path, ".gltf");
}

// Lighting inputs: canopy-haar's .chaar or canopy-lbsolve's PLANT.light.vdb.
bool isLightPath(const std::string& p) { return endsWith(p, ".chaar") || endsWith(p, ".light.vdb"); }

// The hash in a source label "<path> xxh64:<hex>" ("" if there is none).
std::string contentHashOf(const std::string& label) {
  const auto at = label.rfind(" xxh64:");
  return at == std::string::npos ? std::string() : label.substr(at + 7);
}

// One plant: PLANT.density.vdb [PLANT.light.chaar|.vdb], one identity instance.
Scene singlePlant(const std::vector<std::string>& inputs) {
  if (inputs.empty()) throw usageError("no input: give PLANT.density.vdb [PLANT.light.chaar] or --scene SCENE.json|SCENE.glb");
  if (inputs.size() > 2) throw usageError("one plant takes PLANT.density.vdb and at most one PLANT.light.chaar");
  SceneModel m;
  m.name = stemOf(inputs[0]);
  m.density = inputs[0];
  if (inputs.size() == 2) {
    if (!endsWith(inputs[1], ".chaar") && !endsWith(inputs[1], ".vdb"))
      throw usageError(inputs[1] + ": the second input must be lighting: PLANT.light.chaar (canopy-haar) or PLANT.light.vdb (canopy-lbsolve)");
    m.light = inputs[1];
  }
  SceneInstance identity;
  identity.matrix = {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1};
  Scene s;
  s.models.push_back(m);
  s.instances.push_back(identity);
  return s;
}

// --scene SCENE.glb LATTICE.density.vdb [LIGHT] ...: the scene's models and instances as
// canopy-voxelize --instances lists them (mesh::sceneFromGltf), each model's density being the
// lattice that canopy-voxelize SCENE.glb --mesh N wrote for its mesh: matched by the lattice's
// metadata (the glTF's content hash and the mesh index), not by file names. A lighting input
// (.chaar or .light.vdb) belongs to the lattice just before it.
Scene gltfScene(const std::string& glb, const std::vector<std::string>& inputs) {
  Scene scene = mesh::sceneFromGltf(glb);
  auto meshLabel = [&](const SceneModel& m) { return "mesh " + std::to_string(m.mesh) + " ('" + m.name + "')"; };
  Scene named = scene;  // canopy-voxelize's default lattice names, for the hints
  mesh::applyModelPattern(named, glb, "{stem}.mesh{N}.density.vdb");
  auto voxelizeHint = [&](size_t model) {
    return "canopy-voxelize " + glb + " --mesh " + std::to_string(named.models[model].mesh) + " -o " + named.models[model].density;
  };
  if (inputs.empty())
    throw usageError(glb + ": give the density lattice of each of its " + std::to_string(scene.models.size()) +
                     " meshes (e.g. " + voxelizeHint(0) + "), each followed by its optional lighting");
  const std::string sceneHash = contentHashOf(scene.source);
  std::map<int, size_t> modelOfMesh;
  for (size_t i = 0; i < scene.models.size(); ++i) modelOfMesh[scene.models[i].mesh] = i;
  SceneModel* last = nullptr;  // the model of the previous density input (for its lighting)
  for (const std::string& in : inputs) {
    if (isLightPath(in)) {
      if (!last || !last->light.empty())
        throw usageError(in + ": a lighting input must follow the density lattice it lights");
      last->light = in;
      continue;
    }
    const vdbio::DensityLatticeOrigin origin = vdbio::readDensityLatticeOrigin(in);
    if (contentHashOf(origin.source) != sceneHash)
      throw invalidInput(in + ": voxelised from '" + origin.source + "', not from the scene " + scene.source);
    if (!origin.hasMeshIndex || origin.meshIndex < 0)
      throw invalidInput(in + ": voxelised from the whole of " + glb + ", not from one of its meshes (canopy-voxelize --mesh N)");
    const auto it = modelOfMesh.find(origin.meshIndex);
    if (it == modelOfMesh.end())
      throw invalidInput(in + ": voxelised from mesh " + std::to_string(origin.meshIndex) + ", which no node of " + glb + " uses");
    last = &scene.models[it->second];
    if (!last->density.empty()) throw invalidInput(in + ": " + meshLabel(*last) + " already has a lattice (" + last->density + ")");
    last->density = in;
  }
  for (size_t i = 0; i < scene.models.size(); ++i)
    if (scene.models[i].density.empty())
      throw invalidInput(glb + ": " + meshLabel(scene.models[i]) + " has no lattice among the inputs (" + voxelizeHint(i) + ")");
  return scene;
}

// The scene to pack (one plant, a glTF scene or a scene list), checked before any work; notes its source in meta.
Scene packScene(const OctreepackOptions& o, nlohmann::json& meta) {
  Scene scene;
  if (o.scene.empty()) {
    scene = singlePlant(o.inputs);
  } else if (isGltf(o.scene)) {
    scene = gltfScene(o.scene, o.inputs);
  } else {
    if (!o.inputs.empty())
      throw usageError(o.inputs[0] + ": --scene SCENE.json names its own models; lattice inputs go with --scene SCENE.glb");
    scene = readSceneJson(o.scene);
  }
  // The file the instances were computed from: the glTF (directly, or through the "source" of
  // the list canopy-voxelize --instances wrote from it), else the hand-written list itself.
  if (!o.scene.empty()) meta["scene"] = scene.source.empty() ? o.scene : scene.source;
  if (o.output.empty()) throw usageError("no output: give -o OUT.canopy");
  for (const SceneModel& m : scene.models) {
    requireReadableFile(m.density);
    if (!m.light.empty() && !o.ignoreLight) requireReadableFile(m.light);
  }
  return scene;
}

// --scene-light: the scene lattice's light into the file.
void addSceneLight(const OctreepackOptions& o, CanopyWriteInput& w, nlohmann::json& meta) {
  SceneLightSource sl = readSceneLightVdb(o.sceneLight, o.sceneLightGrid);
  w.hasSceneLight = true;
  w.sceneLight = sl.header;
  w.sceneLightBases = sl.bases;
  w.sceneLightValues = std::move(sl.values);
  meta["scene_light"] = sl.sourceLabel;
  if (!o.sceneLightGrid.empty()) meta["scene_light_grid"] = o.sceneLightGrid;
}

// One model built: its octree, its .chaar Haar pages (or null) and its entry in the metadata.
struct PackedModel {
  BuiltModel built;
  std::shared_ptr<const CanopyHaarPages> haar;
  nlohmann::json source;
};

// Builds model i's octree, with its lighting unless --ignore-light.
PackedModel packModel(const OctreepackOptions& o, const SceneModel& m, size_t i) {
  logInfo("canopy-octreepack: model " + std::to_string(i) + " '" + m.name + "' from " + m.density);
  ModelSource src = readDensityVdb(m.density, m.name);
  nlohmann::json source = {{"name", m.name}, {"density", src.sourceLabel}};
  LightFn light;
  std::shared_ptr<const CanopyHaarPages> haar;  // .chaar lighting: its bricks, the finest level's exact light
  bool scatteredSun = false;
  if (!m.light.empty() && !o.ignoreLight) {
    LightVdb lv = endsWith(m.light, ".chaar") ? readChaarLight(m.light, src, !o.noHaarLight) : readLightVdb(m.light, src);
    light = std::move(lv.fn);
    haar = std::move(lv.haar);
    scatteredSun = lv.scatteredSun;
    source["light"] = lv.sourceLabel;
    source["sun_bases"] = scatteredSun ? "scattered" : "total";
    if (!scatteredSun)
      logWarn(m.light + ": its sun bases include the direct beam (canopy-lbsolve --sun-bases total, or a light file "
              "from before 2026-12): canopy-play will count the direct sun twice; re-run canopy-lbsolve");
  }
  PackedModel p{buildOctree(src, m.density, light), std::move(haar), std::move(source)};
  if (scatteredSun) p.built.record.flags |= kCanopyModelScatteredSun;
  return p;
}

}  // namespace

nlohmann::json octreepack(const OctreepackOptions& o) {
  const auto t0 = std::chrono::steady_clock::now();
  if (o.pageCoding != "zstd" && o.pageCoding != "raw") throw usageError("--pages must be zstd or raw, got '" + o.pageCoding + "'");
  nlohmann::json meta = {{"tool", "canopy-octreepack"}, {"version", versionString()}};
  const Scene scene = packScene(o, meta);

  CanopyWriteInput w;
  if (!o.sceneLight.empty()) addSceneLight(o, w, meta);  // read first: a bad scene lattice fails before the models are built
  std::vector<BuiltModel> built;
  built.reserve(scene.models.size());
  std::vector<std::shared_ptr<const CanopyHaarPages>> haarPages;  // per model, or null
  nlohmann::json sources = nlohmann::json::array();
  Progress progress("octreepack models", int64_t(scene.models.size()));
  for (size_t i = 0; i < scene.models.size(); ++i) {
    PackedModel p = packModel(o, scene.models[i], i);
    built.push_back(std::move(p.built));
    haarPages.push_back(std::move(p.haar));
    sources.push_back(p.source);
    progress.add();
  }
  for (size_t i = 0; i < built.size(); ++i)
    w.models.push_back({built[i].record, &built[i].tiles, &built[i].bricks, &built[i].light, haarPages[i].get()});
  for (const SceneInstance& in : scene.instances) {
    CanopyInstance ci{};
    for (int k = 0; k < 12; ++k) ci.modelToWorld[k] = float(in.matrix[size_t(k)]);  // rows 0..2 of the 4x4
    ci.model = in.model;
    w.instances.push_back(ci);
  }
  meta["models"] = sources;
  progress.done();
  w.metadata = meta.dump();
  w.pageCoding = o.pageCoding == "raw" ? kCanopyPageRaw : kCanopyPageZstd;
  w.zstdLevel = o.zstdLevel;
  const CanopyWriteStats stats = writeCanopyFile(o.output, std::move(w));

  nlohmann::json report = canopyInfo(CanopyFile::open(o.output));
  report["output"] = o.output;
  report["seconds"] = secondsSince(t0);
  uint64_t cells = 0;
  for (const auto& b : built) cells += b.occupiedCells;
  report["occupied_cells"] = cells;
  logInfo("canopy-octreepack: wrote " + o.output + " (" + std::to_string(stats.fileBytes) + " bytes, resident " +
          std::to_string(stats.residentBytes) + ", " + std::to_string(stats.pageCount) + " pages" +
          (stats.pageCoding == kCanopyPageZstd ? ", compressed from " + std::to_string(stats.pageBytes) + " bytes" : std::string()) + ")");
  return report;
}

nlohmann::json canopyInfo(const CanopyFile& f) {
  const CanopyFileHeader& h = f.header();
  nlohmann::json j;
  j["file"] = f.path();
  j["format_version"] = std::to_string(h.major) + "." + std::to_string(h.minor);
  j["file_bytes"] = h.fileBytes;
  j["resident_bytes"] = h.residentBytes;
  j["resident_fraction"] = h.fileBytes ? double(h.residentBytes) / double(h.fileBytes) : 0.0;
  j["page_bytes"] = h.pageBytes;
  j["pages"] = h.pageCount;
  // (5.0) how the pages are stored, and the bytes they take against their images'
  j["page_coding"] = h.pageCoding == kCanopyPageZstd ? "zstd" : "raw";
  j["pages_stored_bytes"] = f.storedPageBytes();
  j["pages_image_bytes"] = uint64_t(h.pageCount) * h.pageBytes;
  j["bricks_per_page"] = h.bricksPerPage;
  // the light items' encoding (canopy_layout.h): shared-exponent RGB words from 4.0, float16 before
  j["light_items"] = h.major >= 4 ? "rgb9e5" : "float16";
  j["instances"] = h.instanceCount;
  nlohmann::json sections = nlohmann::json::array();
  for (uint32_t i = 0; i < f.sectionCount(); ++i) {
    const CanopySection& s = f.section(i);
    sections.push_back({{"name", canopySectionLabel(s.kind)}, {"offset", s.offset}, {"bytes", s.bytes}, {"items", s.itemCount}});
  }
  sections.push_back({{"name", "pages"}, {"offset", h.pagesOffset}, {"bytes", f.storedPageBytes()}, {"items", h.pageCount}});
  j["sections"] = sections;
  nlohmann::json models = nlohmann::json::array();
  for (uint32_t m = 0; m < f.modelCount(); ++m) {
    const CanopyModel& M = f.model(m);
    nlohmann::json levels = nlohmann::json::array();
    // Node kinds per level, by walking the (already validated) tree.
    std::vector<uint64_t> empty(M.depth + 1, 0), constant(M.depth + 1, 0), brick(M.depth + 1, 0);
    std::vector<std::pair<CanopyNode, uint32_t>> stack{{M.root, 0}};
    while (!stack.empty()) {
      auto [n, level] = stack.back();
      stack.pop_back();
      if (n.brick != kCanopyNone) ++brick[level];
      else if (n.density == 0.0f) ++empty[level];
      else ++constant[level];
      if (n.child != kCanopyNone)
        for (int c = 0; c < 8; ++c) stack.emplace_back(f.tiles(m)[size_t(n.child) * 8 + c], level + 1);
    }
    for (uint32_t d = 0; d <= M.depth; ++d)
      levels.push_back({{"level", d}, {"voxel_cells", M.rootCells / (kCanopyBrickSize << d)}, {"bricks", brick[d]},
                        {"constant_nodes", constant[d]}, {"empty_nodes", empty[d]}});
    uint32_t instances = 0;
    for (uint32_t i = 0; i < f.instanceCount(); ++i) instances += f.instance(i).model == m;
    models.push_back({{"name", std::string(M.name)},
                      {"lattice_min", {M.latticeMin[0], M.latticeMin[1], M.latticeMin[2]}},
                      {"lattice_max", {M.latticeMax[0], M.latticeMax[1], M.latticeMax[2]}},
                      {"light_lattice_min", {M.latticeMin[0] >> M.detailLevels, M.latticeMin[1] >> M.detailLevels, M.latticeMin[2] >> M.detailLevels}},
                      {"light_lattice_max", {M.latticeMax[0] >> M.detailLevels, M.latticeMax[1] >> M.detailLevels, M.latticeMax[2] >> M.detailLevels}},
                      {"detail_levels", M.detailLevels},
                      {"sparse_bricks", M.sparseBricks},
                      {"sparse_pages", M.sparsePageCount},
                      {"light_depth", canopyLightDepth(M)},
                      {"depth", M.depth},
                      {"root_cells", M.rootCells},
                      {"tiles", M.tileCount},
                      {"nodes", 1 + uint64_t(M.tileCount) * 8},
                      {"bricks", M.brickCount},
                      {"brick_pages", M.brickPageCount},
                      {"light_pages", M.lightPageCount},
                      {"light_items", M.lightCount},
                      {"has_light", (M.flags & kCanopyModelHasLight) != 0},
                      {"haar_light", (M.flags & kCanopyModelHaarLight) != 0},
                      {"sun_bases", !(M.flags & kCanopyModelHasLight) ? "none" : (M.flags & kCanopyModelScatteredSun) ? "scattered" : "total"},
                      {"haar_pages", M.haarPageCount},
                      {"haar_items", M.haarItemCount},
                      {"haar_precision", M.haarPrecision ? "fp16" : "fp32"},
                      {"instances", instances},
                      {"levels", levels}});
  }
  j["models"] = models;
  j["scene_light"] = f.hasSceneLight();
  if (f.hasSceneLight()) {
    const auto& s = f.sceneLight();
    j["scene_light_dim"] = {s.dim[0], s.dim[1], s.dim[2]};
  }
  j["scene_light_bases"] = f.sceneLightBases();  // 0 (none), 1 (B00: one factor) or 19 (B00..B18)
  return j;
}

std::string formatInfo(const nlohmann::json& j) {
  std::ostringstream o;
  o << j["file"].get<std::string>() << ": .canopy " << j["format_version"].get<std::string>() << ", "
    << j["file_bytes"].get<uint64_t>() << " bytes, resident " << j["resident_bytes"].get<uint64_t>() << " ("
    << 100.0 * j["resident_fraction"].get<double>() << "%), " << j["pages"].get<uint64_t>() << " pages of "
    << j["page_bytes"].get<uint64_t>() << " bytes";
  if (j["page_coding"].get<std::string>() == "zstd")
    o << " compressed (zstd) to " << j["pages_stored_bytes"].get<uint64_t>() << " bytes ("
      << 100.0 * double(j["pages_stored_bytes"].get<uint64_t>()) / double(std::max<uint64_t>(1, j["pages_image_bytes"].get<uint64_t>())) << "%)";
  o << ", " << j["instances"].get<uint64_t>() << " instances\n";
  o << "sections:\n";
  for (const auto& s : j["sections"])
    o << "  " << s["name"].get<std::string>() << ": " << s["bytes"].get<uint64_t>() << " bytes at " << s["offset"].get<uint64_t>() << "\n";
  if (j["scene_light"].get<bool>()) {
    const auto& d = j["scene_light_dim"];
    o << "scene light: " << d[0].get<int>() << "x" << d[1].get<int>() << "x" << d[2].get<int>() << " nodes, "
      << j["scene_light_bases"].get<uint32_t>() << (j["scene_light_bases"].get<uint32_t>() == 1 ? " base (B00: one factor for all indirect light)\n"
                                                                                          : " bases (B00 ambient, B01..B18 sun)\n");
  }
  for (const auto& m : j["models"]) {
    o << "model '" << m["name"].get<std::string>() << "': depth " << m["depth"].get<uint32_t>() << " (" << m["root_cells"].get<uint32_t>()
      << " cells/axis), " << m["nodes"].get<uint64_t>() << " nodes, " << m["bricks"].get<uint64_t>() << " bricks in "
      << m["brick_pages"].get<uint64_t>() << " pages, " << m["instances"].get<uint64_t>() << " instances, light: "
      << (m["has_light"].get<bool>() ? "yes (" + std::to_string(m["light_pages"].get<uint64_t>()) + " pages of " + j["light_items"].get<std::string>() + " items" +
                                           (m["haar_light"].get<bool>() ? "; the finest level's exact light: " + std::to_string(m["haar_items"].get<uint64_t>()) +
                                                                              " Haar bricks (" + m["haar_precision"].get<std::string>() + ") in " +
                                                                              std::to_string(m["haar_pages"].get<uint64_t>()) + " pages"
                                                                        : std::string()) +
                                           "; sun bases " + m["sun_bases"].get<std::string>() + ")"
                                     : std::string("no"))
      << "\n";
    auto box = [](const nlohmann::json& lo, const nlohmann::json& hi) {
      std::ostringstream b;
      for (int a = 0; a < 3; ++a) b << (a ? "x" : "") << hi[a].get<int64_t>() - lo[a].get<int64_t>() + 1;
      return b.str();
    };
    const uint32_t detail = m["detail_levels"].get<uint32_t>();
    o << "  density lattice " << box(m["lattice_min"], m["lattice_max"]) << ", light lattice "
      << box(m["light_lattice_min"], m["light_lattice_max"])
      << (detail ? " (detail x" + std::to_string(1u << detail) + ": levels " + std::to_string(m["light_depth"].get<uint32_t>() + 1) +
                       ".." + std::to_string(m["depth"].get<uint32_t>()) + " take the light of level " +
                       std::to_string(m["light_depth"].get<uint32_t>()) + "; their " + std::to_string(m["sparse_bricks"].get<uint64_t>()) +
                       " bricks sparse, in " + std::to_string(m["sparse_pages"].get<uint64_t>()) + " pages)"
                 : std::string(" (the same)"))
      << "\n";
    for (const auto& l : m["levels"])
      o << "  level " << l["level"].get<uint32_t>() << " (voxel = " << l["voxel_cells"].get<uint32_t>() << " cells): "
        << l["bricks"].get<uint64_t>() << " bricks, " << l["constant_nodes"].get<uint64_t>() << " constant, "
        << l["empty_nodes"].get<uint64_t>() << " empty\n";
  }
  return o.str();
}

void canopyVerify(const std::string& path, nlohmann::json& report) {
  CanopyFile f = CanopyFile::open(path);  // resident problems throw with their own exit code
  const std::vector<std::string> problems = verifyCanopyPages(f);
  report["file"] = path;
  report["pages_checked"] = f.pageCount();
  report["problems"] = problems;
  report["ok"] = problems.empty();
  if (!problems.empty())
    throw invalidInput(problems.front() + (problems.size() > 1 ? " (and " + std::to_string(problems.size() - 1) + " more problems)" : ""));
}

}  // namespace canopy::octreepack
