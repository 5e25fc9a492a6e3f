// scene.h: the host-side scene of the player, built once from a CanopyFile's resident part.
//
// HostScene holds the arrays that cone.h's SceneView points at (models, instances, the uniform grid
// of instance boxes, the coarse scene light); the backends copy them (the CUDA one to the device)
// and fill in the cache pointers. setSun() recomputes every instance's sun lookup (the sun taken
// into the instance's model/lattice axes, dissertation §4.2) once per frame, and the coarse scene
// lattice's sun factor (the same lookup on its bases, §4.3) where the file has its sun bases. Light pages share the
// brick pages' cache (page table, pool, LRU, loader): see cone.h, 7.
#pragma once
#include <cstdint>
#include <limits>
#include <string>
#include <vector>

#include "formats/canopy_file.h"
#include "runtime/cone.h"

namespace canopy::play {

struct HostScene {
  // Moved, never copied: the models' descent-table pointers point into levelNodes and levelOf.
  HostScene() = default;
  HostScene(HostScene&&) = default;
  HostScene& operator=(HostScene&&) = default;
  HostScene(const HostScene&) = delete;
  HostScene& operator=(const HostScene&) = delete;
  std::vector<ModelView> models;          // tiles point into the CanopyFile's resident tiles
  std::vector<uint32_t> modelFirstTile;   // each model's first tile in CanopyFile::allTiles()
  std::vector<uint32_t> modelFirstHaarIndex;  // each Haar-lit model's first entry in haarIndex
  const std::vector<uint32_t>* haarIndex = nullptr;  // CanopyFile::haarIndex() (models' haar.index point into it)
  std::vector<uint32_t> modelFirstSparseIndex;  // each model's first entry in sparseIndex
  const std::vector<uint32_t>* sparseIndex = nullptr;  // CanopyFile::sparseIndex() (models' sparseIndex point into it)
  // The models' descent tables (ModelView::levelNodes, levelOf), model after model.
  std::vector<CanopyNode> levelNodes;
  std::vector<uint8_t> levelOf;
  std::vector<uint32_t> lightBricks;
  std::vector<uint32_t> modelFirstLevelNode;
  std::vector<InstanceView> instances;
  std::vector<Affine> worldToLatticeLinear;  // per instance: world vectors -> lattice index axes
  std::vector<uint32_t> gridStart, gridItems;
  std::vector<uint32_t> gridFaceStart, gridFaceItems;  // per cell and entry face (SceneView::gridFaceStart)
  int32_t gridDim[3] = {1, 1, 1};
  float gridLo[3] = {0, 0, 0}, gridCell[3] = {1, 1, 1};
  float boundsLo[3] = {0, 0, 0}, boundsHi[3] = {0, 0, 0};  // world bounds of every instance
  bool empty = true;                      // no instance
  FarFieldView far{};                     // the far field's grid (planFarField; values null: each backend builds its own)
  // The world height of the lowest instance base (--ground auto): min over instances of the world y
  // of their model's lowest matter (the bottom of its lowest occupied cell), taken below the centre
  // of the model's lattice (exact for upright instances); +inf without matter.
  float groundBase = std::numeric_limits<float>::infinity();
  bool hasSceneLight = false;
  SceneLightView light{};                 // values == nullptr; backends point it at lightPairs
  uint32_t lightBases = 0;                // the scene lattice's bases: 0 (none), 1 (B00) or 19 (B00..B18)
  std::vector<float> lightBaseValues;     // lightBases x nodes, base-major (CanopyFile::sceneLightValues)
  Affine worldToSceneLinear{};            // world vectors -> scene lattice index axes (for the sun lookup)
  sun::Weights lightSun;                  // the lookup the sun factors were built for
  std::vector<SceneLightPair> lightPairs; // per node {B00, sum_v w_v B_v} (buildSceneLightPairs)
  uint64_t lightVersion = 0;              // incremented whenever lightPairs changes (the CUDA backend re-uploads)
  uint32_t pageCount = 0, pageBytes = 0, bricksPerPage = 0, lightItemsPerPage = 0;
  uint64_t brickPageBytes = 0;            // bytes of all brick pages (streamed)
  uint64_t lightPageBytes = 0;            // bytes of the lit models' light pages (streamed, same cache)
  uint64_t haarPageBytes = 0;             // bytes of the Haar-lit models' Haar pages (streamed with --light exact)
  uint32_t litModels = 0;                 // models sampled with LB light
  uint32_t detailModels = 0;              // models with detail levels (sparse bricks)
  uint32_t haarModels = 0;                // models with Haar light (--light exact)
  uint32_t totalSunModels = 0;            // of them, with sun bases that include the direct beam (counted twice)

  // Sets every instance's sun weights for the direction towards the sun (world), and with a
  // 19-base scene light the sun factors of lightPairs (rebuilt only when the lookup changes).
  void setSun(V3 toSun);
};

// The scene lattice's per-node factor pairs: ambient = B00, sun = sum_v w.weight[v] B_{w.base[v]}
// (in v order, zero weights skipped), with `bases` = 19 and `values` holding B00..B18 base-major
// (nodes values each); with bases = 1 (B00 alone) sun = B00 (one factor for all indirect light).
void buildSceneLightPairs(const std::vector<float>& values, uint32_t bases, size_t nodes, const sun::Weights& w,
                          std::vector<SceneLightPair>& out);

// Builds the scene; throws canopy::Error(InvalidInput) for a degenerate transform.
HostScene buildScene(const CanopyFile& file);

// Builds every model's descent table (ModelView::levelNodes; the player does unless
// --no-descent-table) before the backends are made (at most 37449 nodes, 21 bytes each, per model
// of depth 5 or more); without it a model's tableLevels is 0 and every descent runs from the root.
void addDescentTables(HostScene& scene);

// The scene's extinction grid (kShadowsMap, cone.h): world axes over the scene's bounds with one
// empty voxel of margin on every side; voxel edge shade.shadowMapCells x the smallest instance
// cell, grown until the grid has at most shade.shadowMapMaxVoxels voxels. k is left null.
ExtinctionGridView planExtinctionGrid(const HostScene& scene, const ShadeParams& shade);

// The scene's far field (cone.h farFieldStep): world axes over the scene's bounds with one empty
// voxel of margin on every side; voxel edge the coarsest level's voxel (rootCells / 8 cells), or the
// finest node where that is wider, of the instance whose such voxel is the widest, grown until the
// grid has at most kFarFieldMaxVoxels voxels. values is left null.
constexpr uint32_t kFarFieldMaxVoxels = 1u << 22;  // 64 MiB of 4 floats
FarFieldView planFarField(const HostScene& scene);

// Whether a primary cone of `camera` can reach the scene's far field (scene.far; from shade.farStart,
// or where the footprint reaches its voxel: farFieldStart) inside the scene's bounds; the backends
// build the far field only once one can (the image is the same: a cone that reaches no far field
// marches the instances to its end).
bool farFieldReachable(const HostScene& scene, const ShadeParams& shade, const CameraView& camera);

// The frame's sun transmittance map: its light-space frame (w = -toSun; u, v orthonormal,
// continuous in the sun direction except where -toSun comes within 26 degrees of the x axis, where
// the helper axis switches from x to z), the box around the scene's bounds with one empty voxel of
// margin, and the extinction grid's voxel, grown until the map has at most
// shade.shadowMapMaxVoxels voxels; the lookup bias is shade.shadowMapBias x the larger of a map
// voxel and a finest node (2 extinction voxels). T is left null. `sub` receives the march steps per map voxel
// (at most one extinction voxel each).
ShadowMapView planShadowMap(const HostScene& scene, const ShadeParams& shade, const ExtinctionGridView& grid, int& sub);

// The SceneView over the host arrays (cache pointers left null: the backend sets them).
SceneView hostSceneView(const HostScene& scene);

}  // namespace canopy::play
