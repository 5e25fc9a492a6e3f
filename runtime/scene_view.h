// scene_view.h: the scene as the per-pixel code sees it (plain pointers: host memory on the CPU,
// device memory on the GPU), the shading parameters and the CPU's work counters. Part of runtime/cone.h.
#pragma once
#include "runtime/cone_math.h"

namespace canopy::play {

// ------------------------------------------------------------------------------------------------
// The scene as the kernel sees it (plain pointers: host memory on the CPU, device memory on the GPU)
// ------------------------------------------------------------------------------------------------
#ifndef CANOPY_HIT_CAPACITY  // (a compile-time dial for measurements, e.g. bench/play/variant.sh NAME -DCANOPY_HIT_CAPACITY=8)
#define CANOPY_HIT_CAPACITY 16
#endif
constexpr int kHitCapacity = CANOPY_HIT_CAPACITY;  // instances pending or active along one ray at once (InstanceWalk)
static_assert(kHitCapacity <= 32, "hit bit masks (InstanceWalk::live, traceCone's evaluation mask) are 32 bits");
constexpr uint32_t kFallbackLevels = 3;  // a missing brick may use a resident ancestor this much coarser
constexpr float kMaxConstantCells = 4.0f;  // a uniform non-empty node is shaded at least every 4 cells
constexpr float kStopT = 1e-3f;          // default early stop (ShadeParams::stopT): opacity above 0.999
constexpr float kShadowStopT = 1e-2f;  // a shadow cone stops once 99% of the sun is blocked
constexpr float kShadowReuseT = 0.95f;  // a shadow cone's value serves while the primary T stays above this share
constexpr float kMinContribution = 1e-5f;  // samples below this (T * alpha) are not shaded

struct ModelView {
  const CanopyNode* tiles;  // this model's node tiles (model-relative child indices)
  uint32_t tileCount;
  CanopyNode root;
  uint32_t depth;
  uint32_t rootCells;
  uint32_t firstBrickPage;
  uint32_t hasLight;        // light items present (kCanopyModelHasLight, one per brick of levels 0..lightDepth)
  uint32_t firstLightPage;  // light item b is in page firstLightPage + b / lightItemsPerPage
  uint32_t haarLight;       // also Haar light (kCanopyModelHaarLight): the light lattice's exact light, `haar` below
  uint32_t lightDepth;      // the finest level with light items: depth - detailLevels (a detail brick takes its ancestor's)
  uint32_t lightRootCells;  // light lattice cells per axis under the root: rootCells >> detailLevels
  float extinctionScale;    // light cells per lattice cell, 2^-detailLevels: sigma is per light cell
  int32_t origin[3];        // octreeOrigin >> detailLevels: unit space -> light lattice index space (the Haar lookup)
  CanopyHaarView haar;
  // (2.0) bricks denseBricks.. are sparse bricks (the detail levels): brick b's location is
  // sparseIndex[b - denseBricks] (page within the model's sparse pages << 12 | item)
  uint32_t denseBricks;
  uint32_t firstSparsePage;
  const uint32_t* sparseIndex;
  // The descent table (cone_segment.h descendByTable; ShadeParams::descentTable): for each level
  // L < tableLevels, the node a descent asked for level L reaches in each of the 2^L x 2^L x 2^L
  // cells of that level (x fastest; level L's cells from (8^L - 1) / 7 on); levelOf: that node's
  // level (a leaf ends a descent early) | the level of lightBricks' brick << 4; lightBricks: the
  // brick of the deepest node on that descent's path that has one and lies at most at lightDepth
  // (the light the descent uses where its page is resident; kCanopyNone: none). tableLevels 0: none.
  const CanopyNode* levelNodes;
  const uint8_t* levelOf;
  const uint32_t* lightBricks;
  uint32_t tableLevels;
  uint32_t rootLightPage;  // the light page of the root's brick (kCanopyNone: no root brick, or no light)
};
constexpr uint32_t kDescentTableLevels = 6;  // levels 0..5: (8^6 - 1) / 7 = 37449 nodes per model at most
static_assert(kDescentTableLevels <= 10, "descendByTable indexes a model's table in 32 bits");

struct InstanceView {
  Affine worldToUnit;       // world -> this instance's model octree unit space
  float cellWorld;          // mean world length of one lattice cell (footprint -> cells)
  float unitLo[3], unitHi[3];      // the box of the model's leaves with matter in unit space (the march's extent; every leaf outside is empty)
  float boundsLo[3], boundsHi[3];  // world AABB of that box (for the instance grid)
  uint32_t model;
  sun::Weights sunWeights;  // the sun in this instance's model space -> LB bases (per frame)
};

// The two factors of the coarse scene lattice (lbsolve --scene, dissertation §4.3) at a point:
// the ambient one (B00, 1 = unoccluded sky) on the ambient term, and the sun one (the lattice's
// sun bases weighted by the frame's sun lookup, sum_v w_v B_v: 1 = unoccluded sun) on the
// scattered sun term. A file with B00 alone gives both the value of B00.
struct alignas(8) SceneLightPair {
  float ambient;
  float sun;
};

struct SceneLightView {     // coarse scene lattice (lbsolve --scene), factors on indirect light
  const SceneLightPair* values;  // per node, x fastest (HostScene::setSun builds it); nullptr: none (factors 1)
  Affine worldToIndex;
  int32_t min[3];
  int32_t dim[3];
};

struct ShadeParams {
  V3 toSun;                 // unit vector towards the sun (world)
  float sun[3];             // sun radiance (linear RGB): scales the LB sun bases (lbIndirect)
  float direct[3];          // the direct term's sun radiance: sun, or 0 (--no-direct-sun)
  float ambient;            // ambient factor (user): indirect = ambient * ambient scene factor without LB data
  float sigma;              // extinction per lattice cell at density 1
  float stepFactor;         // brick step in voxels of the chosen level
  float lodBias;            // added to the chosen level (negative = coarser)
  float stopT;              // a cone stops when its transmittance falls below this (kStopT: opacity 0.999)
  // A primary cone's brick steps grow once its transmittance T falls below stepGrowthT: by
  // min(stepGrowthMax, stepGrowthT / T) (stepGrowth, cone.h). 0: never.
  float stepGrowthT;
  float stepGrowthMax;
  float shadowAperture;     // shadow cone: footprint growth per unit length (radians)
  int shadows;              // kShadowsOff (Tshadow = 1), kShadowsMap or kShadowsCone
  float shadowMapCells;     // kShadowsMap: extinction grid voxel in lattice cells of the finest instance
  float shadowMapBias;      // kShadowsMap: lookup offset towards the sun, in blur widths (planShadowMap)
  uint32_t shadowMapMaxVoxels;  // kShadowsMap: voxels grow until a grid has at most this many
  int descentCache;         // 1: reuse a ray's last descent per instance (DescentCache); 0: always descend
  int descentTable;         // 1: a descent reads its node from the model's descent table where that gives the same descent
  int holdEmpty;            // 1: a primary ray keeps an instance's empty leaf segment to its end (EmptyHold)
  int skipEmptyBlocks;      // 1: a brick step in an empty cell goes to the end of the cell run (emptyRunEnd)
  int exactLight;           // 1 (--light exact): the finest level of Haar-lit models samples the Haar pages
  // The ground (groundRadiance): a horizontal plane y = groundY (world, +Y up) that ends every ray
  // from above it that reaches it; 0 (ShadeParams{}): none, rays leave the scene to the sky.
  int ground;
  float groundY;
  float groundAlbedo[3];    // linear RGB
  // Stereo's traced eye (kWithDepth): a pixel's front layer holds its samples within this many
  // pixels of disparity of its first one (ConeResult::frontSums; stereo.h); 0: no layers.
  float stereoLayer;
  // The far field (FarFieldView): < 0 off (instances everywhere); 0 (auto) from where a primary
  // cone's footprint reaches the far field's voxel (farFieldStart); > 0 from this distance on.
  float farStart;
};

// How a sample's sun transmittance Tshadow is found (ShadeParams::shadows).
constexpr int kShadowsOff = 0;
constexpr int kShadowsMap = 1;   // looked up in the frame's sun transmittance map (ShadowMapView)
constexpr int kShadowsCone = 2;  // a shadow cone marched per shadow interval (shadowTransmittance)

// The sun transmittance map of one frame (kShadowsMap): a grid in light space whose third axis
// points along the light's travel (-toSun), so that a column of voxels is a ray from the sun.
// T[u + dim0 (v + dim1 w)] is the transmittance from the sun to the centre of voxel (u, v, w).
// It is built from the scene's extinction grid (buildShadowMapColumn) when the sun's direction has
// changed (Backend::buildShadowMap) and looked up per sample (shadowMapLookup): view-independent,
// so the sun may move every frame.
struct ShadowMapView {
  float* T;                 // dim[0] * dim[1] * dim[2] values, u fastest
  V3 origin;                // world position of voxel (0, 0, 0)'s centre
  V3 axis[3];               // unit axes u, v, w (w = -toSun)
  float voxel;              // voxel edge (world)
  int32_t dim[3];
  float bias;               // lookups move this far towards the sun (world), see shadowMapLookup
};

// The far field (cone.h farFieldStep): the scene prefiltered once per scene by the backend, a grid
// in world axes whose voxel is the coarsest level's voxel of the coarsest instance (planFarField),
// holding at each voxel centre the node-mean extinction of every instance there and that times its
// albedo (buildFarFieldVoxel). A primary cone marches the instances up to the far field's start and
// this grid beyond it, so its cost there no longer depends on how many instances it passes.
constexpr int kFarFieldChannels = 4;  // k, k x albedo (RGB): per world unit
struct FarFieldView {
  float* values;  // kFarFieldChannels per voxel, x fastest; nullptr: no far field
  float lo[3];    // world position of voxel (0, 0, 0)'s centre
  float voxel;    // voxel edge (world)
  int32_t dim[3];
};

// Work done by the CPU reference (bench-play --count-work; never counted on the GPU).
struct WorkCounters {
  uint64_t cones, primarySteps, shadedSamples, segments, descents, brickSamples, shadowCones, shadowSteps, shadowMapLookups,
      shadowMapSteps, heldSegments, emptySteps, zeroBrickSamples, emptyBlockSkips,
      hitDrops,    // hits dropped for good from a full hit list: more than kHitCapacity active at once (InstanceWalk)
      hitRewinds,  // hits put off by a full hit list, found again where the walk adds their cell whole (InstanceWalk)
      farSteps,  // steps of primary cones through the far field (farFieldStep)
      tableDescents;  // descents read from a descent table (descendByTable)
  // The level of detail rule at work (countVoxelFootprint): shading segments by the width of the
  // chosen level's voxel over the pixel's footprint there (in pixels): <= 1, <= 1.5, <= 4, above;
  // and the largest ratio (its float's bits).
  uint64_t voxelPixels[4], maxVoxelPixelsBits;
};

struct SceneView {
  const ModelView* models;
  const InstanceView* instances;
  uint32_t instanceCount;
  // Uniform grid of instance boxes: cell c holds gridItems[gridStart[c] .. gridStart[c + 1]).
  const uint32_t* gridStart;
  const uint32_t* gridItems;
  // The same per entry face: list 6 c + 2 a (+ 1) of gridFaceItems, [gridFaceStart[i] ..
  // gridFaceStart[i + 1]), holds the items of cell c whose cells start at c along +a (end at c
  // along -a): those that the cell behind that face does not list (InstanceWalk).
  const uint32_t* gridFaceStart;
  const uint32_t* gridFaceItems;
  int32_t gridDim[3];
  float gridLo[3], gridCell[3];
  // Streaming cache.
  const int32_t* pageSlot;       // page -> slot in pool, or -1 (missing)
  const unsigned char* pool;     // slot * pageBytes
  uint32_t* slotUsed;            // slot -> stamp of the last frame that sampled it
  uint32_t* pageWanted;          // page -> stamp of the last frame that missed it
  uint32_t stamp;
  uint32_t pageBytes;
  IndexDivisor bricksPerPage;
  uint32_t brickMaskOffset;      // where a brick page image keeps its empty-cell masks (0: no masks, no skip)
  IndexDivisor lightItemsPerPage;
  uint32_t litModels;            // models with LB light (0: renderPixel takes the path without light code)
  uint32_t detailModels;         // models with detail levels (0: the pixel kernels without their code, scenePaths)
  uint32_t haarModels;           // models with Haar light (with --light exact, the pixel kernels with its code)
  SceneLightView light;
  ShadeParams shade;
  ShadowMapView shadowMap;       // kShadowsMap: this pass's sun transmittance map
  FarFieldView far;              // the far field (values nullptr: none, instances everywhere)
  WorkCounters* work;            // CPU only, optional (nullptr: not counted)
};

// The optional paths of a primary cone's march (renderPixelT's kPaths): a pixel kernel is compiled
// with those a frame uses and no others, since code that a frame never runs still costs: on one
// H100 the far field's and the descent table's code, unused, made the real forest's frames 19-25 %
// slower, and the detail levels' code cost 11-14 % (docs/performance.md, "Kernel code size").
//   kPathFar: the far field (a frame whose cones can reach it: s.far.values set);
//   kPathDetail: detail levels' sparse bricks (s.detailModels > 0);
//   kPathTable: descents read from the models' descent tables (s.shade.descentTable);
//   kPathExact: --light exact's Haar light (s.shade.exactLight with a model that has Haar light).
//     A reference mode: compiled only with every other path (kAllPaths), to bound the kernels
//     compiled; apart, the default frames of Haar-lit models leave its code out (docs/performance.md).
constexpr uint32_t kPathFar = 1, kPathDetail = 2, kPathTable = 4, kPathExact = 8, kAllPaths = 15;
CANOPY_HD inline uint32_t scenePaths(const SceneView& s) {
  if (s.shade.exactLight && s.haarModels > 0) return kAllPaths;
  return (s.far.values ? kPathFar : 0u) | (s.detailModels > 0 ? kPathDetail : 0u) | (s.shade.descentTable ? kPathTable : 0u);
}
// Stereo's kernels (the traced eye's, the holes') come in three path sets only, to bound the
// kernels compiled: none, the descent table alone (the default frame of a scene without detail
// levels and far field), and every path for the rest.
CANOPY_HD constexpr uint32_t stereoPaths(uint32_t paths) { return paths == 0 || paths == kPathTable ? paths : kAllPaths; }
// The path set compiled after `paths` (< kAllPaths) for a mode: every set without kPathExact in
// turn, then kAllPaths; or the next of stereo's (a set that stereoPaths keeps as it is).
CANOPY_HD constexpr uint32_t nextPathSet(uint32_t paths, bool stereo) {
  uint32_t next = paths + 1;
  if (next & kPathExact) next = kAllPaths;
  while (stereo && stereoPaths(next) != next) ++next;
  return next;
}

// Adds n to a work counter (host code only; compiled out of the CUDA kernels).
#if defined(__CUDA_ARCH__)
#define CANOPY_PLAY_COUNT(s, field, n) ((void)0)
#else
#define CANOPY_PLAY_COUNT(s, field, n) \
  ((s).work ? (void)__atomic_fetch_add(&(s).work->field, uint64_t(n), __ATOMIC_RELAXED) : (void)0)
#endif

// Stamp stores are benign races (every writer writes the same value); relaxed atomics on the host.
CANOPY_HD CANOPY_FORCEINLINE void writeStamp(uint32_t* p, uint32_t v) {
#if defined(__CUDA_ARCH__)
  *p = v;  // a plain store: testing the old value first (a load the warp waits on) was 2 % slower on the real forest
#else
  if (__atomic_load_n(p, __ATOMIC_RELAXED) != v) __atomic_store_n(p, v, __ATOMIC_RELAXED);
#endif
}

}  // namespace canopy::play
