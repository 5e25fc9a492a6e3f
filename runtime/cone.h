// cone.h: the player's per-pixel code, written once for the CPU reference and the CUDA kernel.
//
// One cone per pixel (GigaVoxels ch. 4 and 6, digest ../shared/reference/gigavoxels-004.md §2-3):
//   1. Instances are found along the ray by a 3D-DDA walk of a uniform world grid of instance
//      bounding boxes (SceneView::grid*). Each instance's box interval [tin, tout) joins a small hit
//      list; the walk only advances once the march reaches the current grid cell's exit, so every
//      instance that starts before the march position is already in the list.
//   2. Instances are marched in LOCK STEP along the world ray parameter t: at each step every
//      instance whose interval contains t contributes a segment (its extinction and albedo there
//      and how far that value is valid); the step ends at the nearest segment end. Overlapping
//      instances therefore add their extinctions at the same points (correct compositing of
//      interpenetrating crowns), and non-overlapping ones are composited in ray order.
//   3. Inside an instance the point goes world -> octree unit space (one affine map: inverse of the
//      instance transform, inverse of indexToModel, lattice -> unit). The octree level comes from
//      the cone's footprint (the coarsest level whose voxel is no larger than the footprint), the
//      descent stops there or at a constant node. A constant node (empty or uniform) is one
//      analytic segment to its exit (empty space skipped by node size; a uniform node is cut into
//      pieces of at most kMaxConstantCells so that lighting is still sampled inside it). A brick
//      node is marched with steps of stepFactor voxels, sampled at the step's midpoint, except
//      where the step starts in an empty cell (a voxel of the brick where the trilinear density is
//      0 throughout, from the masks the loader derives for each brick page): the step then goes to
//      the end of the run of empty cells (emptyRunEnd; ShadeParams::skipEmptyBlocks).
//   4. Opacity of a step of length dt (world) with extinction per lattice cell sigma * density:
//      alpha = 1 - exp(-sigma * density * dt * cellsPerWorld) (the length correction of §2; the
//      stored density is a fraction of a lattice cell, so opacity does not depend on the
//      instance's scale). Front to back: C += T alpha c, T *= 1 - alpha; stop at T < stopT (--stop-opacity).
//   5. Shading of a sample: albedo * (sun * Tshadow + indirect). Tshadow is a shadow cone towards
//      the sun through every instance (the same lock-step march without shading, its footprint
//      starting at the primary cone's and widening by shadowAperture per unit length), traced
//      once per shadow interval (about a voxel of the primary cone) and reused by the samples in
//      it. indirect is the LB light of the dissertation §4.2-4.3, see lbIndirect() and
//      segmentIndirect(): one sample per segment, at the point where the density is sampled, and
//      only for samples that contribute (like the shadow cone).
//   6. Streaming: bricks live in pages. A brick whose page is resident (pageSlot[page] >= 0) is
//      sampled and its slot's use stamp set; a missing page has its want stamp set and the sample
//      falls back to coarser data: a resident ancestor brick up to kFallbackLevels above, else the
//      node's stored mean (a constant segment). Never a hole and never a wait.
//   7. LB light (models with kCanopyModelHasLight): light pages go through the SAME cache as brick
//      pages (one page table, one pool, one LRU; a light page is just a page of another kind, of the
//      same size). Light item b belongs to brick b and covers the same node, so the sample's
//      node-local coordinates are the density's. The light used is that of the deepest brick on the
//      descent path whose light page is resident (the node's own brick, else an ancestor's: a
//      constant node always uses its nearest brick ancestor's, as canopy_file.h says); the node's
//      own light page is asked for when it is missing. Only when no light page on the path is
//      resident yet (a cold start) does the sample get the density-only indirect term
//      (ambient x ambient scene factor), and the coarsest brick's light page is asked for as well.
//      With --light exact (ShadeParams::exactLight), a segment at the finest level of a model that
//      has Haar light (format 1.1) samples the .chaar's brick at its lattice point instead
//      (segmentLight, sampleHaarLbLight), its Haar page used or asked for through the same cache.
#pragma once
#include <math.h>
#include <stddef.h>
#include <stdint.h>
#include <string.h>

#include "canopy/half.h"
#include "canopy/hd.h"
#include "canopy/sun_lookup.h"
#include "formats/canopy_file.h"

// Out of line on the device (large per-sample code called from several places of a kernel: one
// copy instead of one per call site); inline on the host.
#if defined(__CUDA_ARCH__)
#define CANOPY_PLAY_NOINLINE __noinline__
#else
#define CANOPY_PLAY_NOINLINE inline
#endif

namespace canopy::play {

// ------------------------------------------------------------------------------------------------
// Small vector math
// ------------------------------------------------------------------------------------------------
struct V3 {
  float x, y, z;
};
CANOPY_HD CANOPY_FORCEINLINE V3 v3(float x, float y, float z) { return V3{x, y, z}; }
CANOPY_HD CANOPY_FORCEINLINE V3 operator+(V3 a, V3 b) { return V3{a.x + b.x, a.y + b.y, a.z + b.z}; }
CANOPY_HD CANOPY_FORCEINLINE V3 operator-(V3 a, V3 b) { return V3{a.x - b.x, a.y - b.y, a.z - b.z}; }
CANOPY_HD CANOPY_FORCEINLINE V3 operator*(V3 a, float s) { return V3{a.x * s, a.y * s, a.z * s}; }
CANOPY_HD CANOPY_FORCEINLINE float dot(V3 a, V3 b) { return a.x * b.x + a.y * b.y + a.z * b.z; }
CANOPY_HD CANOPY_FORCEINLINE V3 cross(V3 a, V3 b) {
  return V3{a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x};
}
CANOPY_HD CANOPY_FORCEINLINE float length(V3 a) { return sqrtf(dot(a, a)); }
CANOPY_HD CANOPY_FORCEINLINE V3 normalize(V3 a) {
  const float l = length(a);
  return l > 0.0f ? a * (1.0f / l) : a;
}
CANOPY_HD CANOPY_FORCEINLINE float comp(V3 a, int i) { return i == 0 ? a.x : (i == 1 ? a.y : a.z); }

// The four 32-bit words at p (16-byte aligned): one 16-byte load on the GPU (the compiler does not
// merge a struct's scalar loads across branches, nor where it cannot see the alignment), a copy on
// the host. Callers decode the words alike on both, so the CPU tests run their decoding.
struct Words4 {
  uint32_t w[4];
};
CANOPY_HD CANOPY_FORCEINLINE Words4 load16(const void* p) {
  Words4 r;
#if defined(__CUDA_ARCH__)
  const uint4 v = *static_cast<const uint4*>(p);
  r.w[0] = v.x, r.w[1] = v.y, r.w[2] = v.z, r.w[3] = v.w;
#else
  memcpy(&r, p, sizeof r);
#endif
  return r;
}

// A 3x4 row-major affine map. Rows 16-byte aligned: one 16-byte load each on the GPU.
struct alignas(16) Affine {
  float m[12];
};
CANOPY_HD CANOPY_FORCEINLINE V3 applyPoint(const Affine& a, V3 p) {
  return V3{a.m[0] * p.x + a.m[1] * p.y + a.m[2] * p.z + a.m[3], a.m[4] * p.x + a.m[5] * p.y + a.m[6] * p.z + a.m[7],
            a.m[8] * p.x + a.m[9] * p.y + a.m[10] * p.z + a.m[11]};
}
CANOPY_HD CANOPY_FORCEINLINE V3 applyVector(const Affine& a, V3 v) {
  return V3{a.m[0] * v.x + a.m[1] * v.y + a.m[2] * v.z, a.m[4] * v.x + a.m[5] * v.y + a.m[6] * v.z,
            a.m[8] * v.x + a.m[9] * v.y + a.m[10] * v.z};
}

// Ray/box slab test: [t0, t1] of o + t d inside [lo, hi] (t0 > t1 = miss).
CANOPY_HD inline void rayBox(V3 o, V3 d, V3 lo, V3 hi, float& t0, float& t1) {
  t0 = -3.0e38f;
  t1 = 3.0e38f;
  for (int a = 0; a < 3; ++a) {
    const float oa = comp(o, a), da = comp(d, a), l = comp(lo, a), h = comp(hi, a);
    if (fabsf(da) < 1e-30f) {
      if (oa < l || oa > h) {
        t0 = 1.0f, t1 = 0.0f;
        return;
      }
      continue;
    }
    const float inv = 1.0f / da;
    float ta = (l - oa) * inv, tb = (h - oa) * inv;
    if (ta > tb) {
      const float s = ta;
      ta = tb, tb = s;
    }
    t0 = ta > t0 ? ta : t0;
    t1 = tb < t1 ? tb : t1;
  }
}

// Division by a run-time constant without a division instruction (the GPU has none: its integer
// division is a ~20-instruction sequence): q = n / d = the high 64 bits of c * n with c = ceil(2^64 / d),
// exact for every 32-bit n and 2 <= d < 2^32 (Lemire, Kaser and Kurz 2019, "Faster remainder by
// direct computation", theorem 1 with F = 64, N = 32: c * d - 2^64 < d, so the error term stays
// below 1/d). c = 0 stands for d = 1.
struct IndexDivisor {
  uint64_t c;
  uint32_t d;
};
inline IndexDivisor indexDivisor(uint32_t d) { return IndexDivisor{d > 1 ? ~uint64_t(0) / d + 1 : 0, d > 0 ? d : 1}; }
// n / d, and n % d in rem.
CANOPY_HD CANOPY_FORCEINLINE uint32_t divide(const IndexDivisor& v, uint32_t n, uint32_t& rem) {
#if defined(__CUDA_ARCH__)
  const uint32_t q = v.c != 0 ? uint32_t(__umul64hi(v.c, uint64_t(n))) : n;
#else
  const uint32_t q = v.c != 0 ? uint32_t((unsigned __int128)v.c * n >> 64) : n;
#endif
  rem = n - q * v.d;
  return q;
}

// ------------------------------------------------------------------------------------------------
// The scene as the kernel sees it (plain pointers: host memory on the CPU, device memory on the GPU)
// ------------------------------------------------------------------------------------------------
constexpr int kHitCapacity = 16;        // instances pending or active along one ray at once
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
  uint32_t hasLight;        // light items present (kCanopyModelHasLight, lightCount == brickCount)
  uint32_t firstLightPage;  // light item b is in page firstLightPage + b / lightItemsPerPage
  uint32_t haarLight;       // also Haar light (kCanopyModelHaarLight): the finest level's exact light, `haar` below
  int32_t origin[3];        // octreeOrigin: unit space -> lattice index space (for the Haar lookup)
  CanopyHaarView haar;
};

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
  float shadowAperture;     // shadow cone: footprint growth per unit length (radians)
  int shadows;              // kShadowsOff (Tshadow = 1), kShadowsMap or kShadowsCone
  float shadowMapCells;     // kShadowsMap: extinction grid voxel in lattice cells of the finest instance
  float shadowMapBias;      // kShadowsMap: lookup offset towards the sun, in blur widths (planShadowMap)
  uint32_t shadowMapMaxVoxels;  // kShadowsMap: voxels grow until a grid has at most this many
  int descentCache;         // 1: reuse a ray's last descent per instance (DescentCache); 0: always descend
  int holdEmpty;            // 1: a primary ray keeps an instance's empty leaf segment to its end (EmptyHold)
  int skipEmptyBlocks;      // 1: a brick step in an empty cell goes to the end of the cell run (emptyRunEnd)
  int exactLight;           // 1 (--light exact): the finest level of Haar-lit models samples the Haar pages
  // The ground (groundRadiance): a horizontal plane y = groundY (world, +Y up) that ends every ray
  // from above it that reaches it; 0 (ShadeParams{}): none, rays leave the scene to the sky.
  int ground;
  float groundY;
  float groundAlbedo[3];    // linear RGB
};

// How a sample's sun transmittance Tshadow is found (ShadeParams::shadows).
constexpr int kShadowsOff = 0;
constexpr int kShadowsMap = 1;   // looked up in the frame's sun transmittance map (ShadowMapView)
constexpr int kShadowsCone = 2;  // a shadow cone marched per shadow interval (shadowTransmittance)

// The sun transmittance map of one frame (kShadowsMap): a grid in light space whose third axis
// points along the light's travel (-toSun), so that a column of voxels is a ray from the sun.
// T[u + dim0 (v + dim1 w)] is the transmittance from the sun to the centre of voxel (u, v, w).
// It is built per render pass from the scene's extinction grid (buildShadowMapColumn) and looked
// up per sample (shadowMapLookup): view-independent, so the sun may move every frame.
struct ShadowMapView {
  float* T;                 // dim[0] * dim[1] * dim[2] values, u fastest
  V3 origin;                // world position of voxel (0, 0, 0)'s centre
  V3 axis[3];               // unit axes u, v, w (w = -toSun)
  float voxel;              // voxel edge (world)
  int32_t dim[3];
  float bias;               // lookups move this far towards the sun (world), see shadowMapLookup
};

// Work done by the CPU reference (bench-play --count-work; never counted on the GPU).
struct WorkCounters {
  uint64_t cones, primarySteps, shadedSamples, segments, descents, brickSamples, shadowCones, shadowSteps, shadowMapLookups,
      shadowMapSteps, heldSegments, emptySteps, zeroBrickSamples, emptyBlockSkips,
      hitDrops;  // hits dropped from a full hit list (InstanceWalk)
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
  SceneLightView light;
  ShadeParams shade;
  ShadowMapView shadowMap;       // kShadowsMap: this pass's sun transmittance map
  WorkCounters* work;            // CPU only, optional (nullptr: not counted)
};

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
  if (*p != v) *p = v;
#else
  if (__atomic_load_n(p, __ATOMIC_RELAXED) != v) __atomic_store_n(p, v, __ATOMIC_RELAXED);
#endif
}

// ------------------------------------------------------------------------------------------------
// Lighting
// ------------------------------------------------------------------------------------------------

// The coarse scene factors at world point p (trilinear, clamped to the lattice; 1 without one):
// one trilinear lookup of the node pairs (a pair is one 8-byte load per corner). Branch-free: the
// eight corners' offsets are fixed before any is read (a corner past the lattice's last node reads
// that node, with weight 0 unless the lattice is one node thick there), so the eight loads issue
// together; the sum is taken in corner order as w_c x value_c (a zero weight adds +0, as the
// skipped term did: the same bits as the loop that skipped it, measured 18-21 % of the real
// forest's frame on an H200 before the change).
CANOPY_HD inline SceneLightPair sceneLightFactors(const SceneLightView& L, V3 p) {
  if (!L.values) return SceneLightPair{1.0f, 1.0f};
  const V3 q = applyPoint(L.worldToIndex, p);
  int i0[3];
  float f[3];
  for (int a = 0; a < 3; ++a) {
    float x = comp(q, a) - float(L.min[a]);
    const float hi = float(L.dim[a] - 1);
    x = x < 0.0f ? 0.0f : (x > hi ? hi : x);
    const float fl = floorf(x);
    i0[a] = int(fl);
    f[a] = x - fl;
    if (i0[a] >= L.dim[a] - 1) i0[a] = L.dim[a] > 1 ? L.dim[a] - 2 : 0, f[a] = L.dim[a] > 1 ? 1.0f : 0.0f;
  }
  const size_t sy = size_t(L.dim[0]), sz = size_t(L.dim[0]) * size_t(L.dim[1]);
  const size_t ox = L.dim[0] > 1 ? 1 : 0, oy = L.dim[1] > 1 ? sy : 0, oz = L.dim[2] > 1 ? sz : 0;
  const SceneLightPair* b = L.values + size_t(i0[0]) + sy * size_t(i0[1]) + sz * size_t(i0[2]);
  SceneLightPair n[8];
  for (int c = 0; c < 8; ++c) n[c] = b[((c & 1) ? ox : 0) + ((c & 2) ? oy : 0) + ((c & 4) ? oz : 0)];
  SceneLightPair v{0.0f, 0.0f};
  for (int c = 0; c < 8; ++c) {
    const int dx = c & 1, dy = (c >> 1) & 1, dz = (c >> 2) & 1;
    const float w = (dx ? f[0] : 1 - f[0]) * (dy ? f[1] : 1 - f[1]) * (dz ? f[2] : 1 - f[2]);
    v.ambient += w * n[c].ambient;
    v.sun += w * n[c].sun;
  }
  return v;
}

// B_0's boundary holds f_i = 1 on all 19 directions, so where nothing occludes the 18 moving
// populations arrive whole and B_0 = 18 (f_0 stays 0 in empty space). Scaling B_0 by 1/18 makes it
// the unoccluded-sky fraction: the same unit as the density-only path's B_0 = 1 (ambientOnly), so
// `--ambient` means the same with and without LB light. (A sun base B_j is 1 in open space.)
constexpr float kAmbientB0Scale = 1.0f / 18.0f;

// The LB indirect light of the dissertation §4.2-4.3 at one sample, given the values of the three
// sun bases chosen by the polyhedron lookup (bases[v] = B_{w.base[v]} there, RGB) and of the
// ambient base B_0, each term relit by the coarse scene lattice (§4.3: the same lookup on its
// bases): (sum_v w_v B_v) * sun * scene.sun + ambient B_0 / 18 * scene.ambient.
// The bases are solved for a unit sun, so their sum is scaled by the sun radiance like the direct
// term. canopy-lbsolve stores the sun bases without their direct beam (kCanopyModelScatteredSun):
// this is then the light scattered at least once, and the shadowed direct sun is the caller's
// `sun * Tshadow`. Bases that include the beam (older files) count it twice (docs/play.md).
CANOPY_HD inline void lbIndirect(const sun::Weights& w, const float bases[3][3], const float b0[3], const float sun[3],
                                 float ambient, SceneLightPair scene, float out[3]) {
  for (int c = 0; c < 3; ++c)
    out[c] = (w.weight[0] * bases[0][c] + w.weight[1] * bases[1][c] + w.weight[2] * bases[2][c]) * sun[c] * scene.sun +
             ambient * kAmbientB0Scale * b0[c] * scene.ambient;
}

// The indirect light of a sample of a model without LB light (or of a lit model before any of its
// light pages is resident): the ambient term alone, B_0 taken as 1: ambient * scene.ambient.
CANOPY_HD inline void ambientOnly(const SceneView& s, SceneLightPair scene, float out[3]) {
  const float zero[3][3] = {{0, 0, 0}, {0, 0, 0}, {0, 0, 0}};
  const float b0[3] = {1.0f / kAmbientB0Scale, 1.0f / kAmbientB0Scale, 1.0f / kAmbientB0Scale};
  const sun::Weights none;
  lbIndirect(none, zero, b0, s.shade.sun, s.shade.ambient, scene, out);
}

// The LB indirect light from a Haar item (--light exact at the finest level of a Haar-lit model) at
// the brick-local footprint `at`: (sum_v w_v B_v) * sun * sunFactor + ambient B_0 / 18 * ambientFactor,
// as lbIndirect() computes it (the same terms in the same order), each base haar::sampleBrick of the item (bit for
// bit the .chaar's own chaarSample). item == nullptr: no light stored there (every base 0).
// On the device this is one out-of-line function, one copy of the sampler for both precisions, the
// four bases in a rolled loop. Measured on the grove at 1080p on an H200 (docs/performance.md): inlined
// per base, precision and call site the decoder made the lit pixel kernel 10x larger (44.7 k PTX
// lines against 4.7 k) and the frame 257.7 ms; out of line 195.0 ms; out of line with its
// coefficient loops rolled too (a fifth of the code) 377.9 ms (all with the sampler that rebuilt the
// footprint's 8 texels as the decoder does). With the weighted-sum sampler (one loop over the
// footprint's kept coefficients, haar_brick.h) the grove takes 17.3 ms, the float16 items
// (--light fast) 16.4 ms (2026-12-01).
// The sun radiance comes by value: a pointer into the kernel's parameters, passed to this
// out-of-line function, made the whole lit kernel 10 % slower on the grove (measured: 18.0 against
// 16.3 ms per 1080p frame on an H200), although --light fast never calls it.
CANOPY_HD CANOPY_PLAY_NOINLINE void sampleHaarLbLight(const unsigned char* item, uint32_t fp16, const haar::BrickLookup& at,
                                                      const sun::Weights& w, haar::Rgb sun, float ambient,
                                                      float sunFactor, float ambientFactor, float out[3]) {
  float acc[3] = {0.0f, 0.0f, 0.0f};
  if (item) {
    const uint32_t base[4] = {uint32_t(w.base[0]), uint32_t(w.base[1]), uint32_t(w.base[2]), 0u};
    const float weight[4] = {w.weight[0], w.weight[1], w.weight[2], ambient * kAmbientB0Scale};
#if defined(__CUDA_ARCH__)
#pragma unroll 1
#endif
    for (int v = 0; v < 4; ++v) {
      if (v == 3) {  // the three sun bases are summed: scale them by the sun radiance and the scene's sun factor before B_0 joins
        acc[0] = acc[0] * sun.r * sunFactor;
        acc[1] = acc[1] * sun.g * sunFactor;
        acc[2] = acc[2] * sun.b * sunFactor;
      }
      if (!(weight[v] != 0.0f)) continue;  // a zero weight adds +0 (lbIndirect would add 0 * B)
      const haar::Rgb c = canopyHaarSampleAt(item, fp16, base[v], at);
      const float f = v == 3 ? ambientFactor : 1.0f;  // B_0's term: ambient B_0 / 18 * ambientFactor (x 1 is exact)
      acc[0] += weight[v] * c.r * f;
      acc[1] += weight[v] * c.g * f;
      acc[2] += weight[v] * c.b * f;
    }
  }
  for (int c = 0; c < 3; ++c) out[c] = acc[c];
}

// The LB indirect light from a light item at node-local l in [0,1]^3: the (up to) three sun bases
// of the instance's lookup and B_0, each trilinear (canopySampleLight's interpolation, the corners
// found once), then lbIndirect().
CANOPY_HD inline void sampleLbLight(const uint16_t* item, const sun::Weights& w, float lx, float ly, float lz,
                                    const float sun[3], float ambient, SceneLightPair scene, float out[3]) {
  const CanopyLightCorners k = canopyLightCorners(lx, ly, lz);
  float bases[3][3];
  for (int v = 0; v < 3; ++v) {
    bases[v][0] = bases[v][1] = bases[v][2] = 0.0f;
    if (w.weight[v] > 0.0f) canopySampleLightAt(item, uint32_t(w.base[v]), k, bases[v]);
  }
  float b0[3];
  canopySampleLightAt(item, 0, k, b0);
  lbIndirect(w, bases, b0, sun, ambient, scene, out);
}

// ------------------------------------------------------------------------------------------------
// One instance's segment at ray position t
// ------------------------------------------------------------------------------------------------
struct Segment {
  float k;          // extinction per world unit
  float albedo[3];
  float tEnd;       // the value holds on [t, tEnd)
  // shading segments with matter only: where the indirect light is sampled
  const uint16_t* lightItem;  // the light item (nullptr: density-only indirect term)
  float light[3];             // the sample's node-local coordinates in the light item's node (Haar: fx, fy, fz)
  float tSample;              // the sample's world ray parameter (scene factor)
  // Haar light (kHaarNone: not used): the item (nullptr: no light stored there) and the packed
  // footprint lx | ly << 2 | lz << 4 | fp16 << 6; light[] then holds the fractions.
  const unsigned char* haarItem;
  uint32_t haarLocal;
};
constexpr uint32_t kHaarNone = 0xFFFFFFFFu;

// Finest level whose voxel (2^(depth - L) lattice cells) is no larger than the footprint.
CANOPY_HD inline uint32_t levelForFootprint(uint32_t depth, float footprintCells, float lodBias) {
  const float fp = footprintCells > 1.0f ? footprintCells : 1.0f;
  float L = float(depth) - floorf(log2f(fp)) + lodBias;
  L = L < 0.0f ? 0.0f : (L > float(depth) ? float(depth) : L);
  return uint32_t(L);
}

// World t at which o + t d (unit space) leaves the node box [lo, lo + size).
CANOPY_HD inline float nodeExit(V3 uo, V3 ud, const float lo[3], float size) {
  float t = 3.0e38f;
  for (int a = 0; a < 3; ++a) {
    const float da = comp(ud, a);
    if (fabsf(da) < 1e-30f) continue;
    const float bound = da > 0.0f ? lo[a] + size : lo[a];
    const float ta = (bound - comp(uo, a)) / da;
    t = ta < t ? ta : t;
  }
  return t;
}

// Descends instance `inst` at unit point u to `maxLevel`, noting the deepest resident brick on the
// way (within kFallbackLevels of maxLevel). Returns the node reached.
//
// Compact (56 bytes): a ray keeps one per pending instance in local memory (DescentCache), where
// the GPU's L1 holds a warp's words of it beside the bricks and nodes it samples; a box on the
// descent path is stored as its level alone (levelBox: the box of that level that holds the node,
// exact since boxes are dyadic). Against the 120 bytes of pointers, boxes and sizes before it, it
// is the same descent, field for field.
constexpr uint8_t kNoLevel = 0xFF;
struct alignas(16) Descent {
  float lo[3];                 // its box: [lo, lo + levelSize(level))   (descentCovers reads these 16 bytes at once)
  uint8_t level;               // its level
  uint8_t maxLevel;            // the level asked for (kNoLevel: an empty DescentCache)
  uint8_t brickLevel;          // the brick to sample: the node's own if resident, else a resident ancestor's (level)
  uint8_t lightLevel;          // LB light (wantLight only): the deepest brick on the path whose light page is resident
  CanopyNode node;             // the node reached
  int32_t brickPoolSlot;       // its page's pool slot; -1: no brick resident
  uint32_t missingPage;        // the node's own page when it was missing, else kCanopyNone
  int32_t lightPoolSlot;       // -1: no light page resident on the path
  uint32_t missingLightPage;   // the deepest brick's light page when it was missing, else kCanopyNone
  uint32_t coarsestLightPage;  // the shallowest brick's light page (asked for on a cold start)
  uint16_t brickSlotInPage;    // the brick's slot in its page (< bricksPerPage)
  uint16_t lightSlotInPage;    // the light item's slot in its page (< lightItemsPerPage)
};
// The reader admits pages of at most 64 MiB (canopy_file.cpp), so slots in a page fit 16 bits.
static_assert(offsetof(Descent, level) == 12 && offsetof(Descent, maxLevel) == 13, "descentCovers' layout");
static_assert((1u << 26) / kCanopyBrickBytes <= 0xFFFFu && (1u << 26) / kCanopyLightItemBytes <= 0xFFFFu,
              "Descent's slots in a page are 16 bits");

// 2^e for |e| < 127, exact, from its exponent bits.
CANOPY_HD CANOPY_FORCEINLINE float pow2i(int e) { return canopyFloatFromBits(uint32_t(127 + e) << 23); }

// The edge of a node of `level` (unit space): 2^-level, as the descent's halvings make it.
CANOPY_HD CANOPY_FORCEINLINE float levelSize(uint32_t level) { return pow2i(-int(level)); }

// The box of `level` (<= d.level) on d's descent path: [lo, lo + size). Every box is dyadic, so
// this is exact: the same bits as the descent's own lo at that level.
CANOPY_HD CANOPY_FORCEINLINE float levelBox(const Descent& d, uint32_t level, float lo[3]) {
  const float size = levelSize(level), scale = pow2i(int(level));
  for (int a = 0; a < 3; ++a) lo[a] = floorf(d.lo[a] * scale) * size;
  return size;
}

// The brick page of d (nullptr: no brick resident), and its light item (nullptr: none resident).
CANOPY_HD CANOPY_FORCEINLINE const unsigned char* descentBrickPage(const SceneView& s, const Descent& d) {
  return d.brickPoolSlot >= 0 ? s.pool + size_t(d.brickPoolSlot) * s.pageBytes : nullptr;
}
CANOPY_HD CANOPY_FORCEINLINE const uint16_t* descentLightItem(const SceneView& s, const Descent& d) {
  return d.lightPoolSlot >= 0 ? canopyLightInPage(s.pool + size_t(d.lightPoolSlot) * s.pageBytes, d.lightSlotInPage) : nullptr;
}

// The pool slot of brick `brick`'s page (-1: not resident); its page and slot in the page.
CANOPY_HD inline int32_t residentSlot(const SceneView& s, const ModelView& m, uint32_t brick, uint32_t& page, uint32_t& inPage) {
  page = m.firstBrickPage + divide(s.bricksPerPage, brick, inPage);
  return s.pageSlot[page];
}

// A node of a tile array, by load16 (on the device every node is 16-byte aligned: the backend's
// tile arrays are device allocations of 16-byte nodes; the host's copy needs no alignment).
CANOPY_HD CANOPY_FORCEINLINE CanopyNode loadNode(const CanopyNode* p) {
  const Words4 v = load16(p);
  CanopyNode n;
  n.child = v.w[0], n.brick = v.w[1], n.density = canopyFloatFromBits(v.w[2]), n.material = v.w[3];
  return n;
}

CANOPY_HD inline Descent descendResident(const SceneView& s, const ModelView& m, V3 u, uint32_t maxLevel, bool wantLight) {
  float x[3] = {u.x, u.y, u.z};
  for (int a = 0; a < 3; ++a) x[a] = x[a] < 0.0f ? 0.0f : (x[a] >= 1.0f ? 0.99999994f : x[a]);
  Descent d;
  d.node = m.root;
  d.lo[0] = d.lo[1] = d.lo[2] = 0.0f;
  d.maxLevel = uint8_t(maxLevel);
  d.brickLevel = d.lightLevel = 0;
  d.brickPoolSlot = -1;
  d.brickSlotInPage = 0;
  d.missingPage = kCanopyNone;
  d.lightPoolSlot = -1;
  d.lightSlotInPage = 0;
  d.missingLightPage = kCanopyNone;
  d.coarsestLightPage = kCanopyNone;
  wantLight = wantLight && m.hasLight;
  const uint32_t firstFallback = maxLevel > kFallbackLevels ? maxLevel - kFallbackLevels : 0;
  float size = 1.0f;
  uint32_t level = 0;
  for (;;) {
    const bool last = !(level < maxLevel && d.node.child != kCanopyNone && d.node.child < m.tileCount);
    if (wantLight && d.node.brick != kCanopyNone) {
      uint32_t inPage;
      const uint32_t lpage = m.firstLightPage + divide(s.lightItemsPerPage, d.node.brick, inPage);
      const int32_t lslot = s.pageSlot[lpage];
      if (d.coarsestLightPage == kCanopyNone) d.coarsestLightPage = lpage;
      if (lslot >= 0) {
        d.lightPoolSlot = lslot;
        d.lightSlotInPage = uint16_t(inPage);
        d.lightLevel = uint8_t(level);
        d.missingLightPage = kCanopyNone;
      } else {
        d.missingLightPage = lpage;
      }
    }
    if (d.node.brick != kCanopyNone && (level >= firstFallback || last)) {
      uint32_t page, inPage;
      const int32_t slot = residentSlot(s, m, d.node.brick, page, inPage);
      if (slot >= 0) {
        d.brickPoolSlot = slot;
        d.brickSlotInPage = uint16_t(inPage);
        d.brickLevel = uint8_t(level);
      } else if (last) {
        d.missingPage = page;
      }
    }
    if (last) break;
    const uint32_t c = canopyStepDown(x, d.lo, size);
    d.node = loadNode(m.tiles + size_t(d.node.child) * 8 + c);
    ++level;
  }
  d.level = uint8_t(level);
  return d;
}

// The last descent of one instance along one ray: a later point inside the node reached, with the
// same level asked for, reaches the same node with the same resident bricks (the page table does
// not change during a pass), so instanceSegment() reuses it instead of descending from the root
// again: a brick node is crossed in about 2 x 8 steps of half a voxel, one descent instead of ~16.
// The result is exactly that of a fresh descent (same node, same brick, same light item).
struct DescentCache {
  Descent d;  // d.maxLevel == kNoLevel: empty (a new hit)
};

// The point u (unit space, clamped as descendResident clamps it) is inside the cached node.
CANOPY_HD CANOPY_FORCEINLINE bool descentCovers(const DescentCache& c, V3 u, uint32_t maxLevel) {
  const Words4 v = load16(&c.d);  // lo, then level and maxLevel (little-endian bytes)
  const float lo[3] = {canopyFloatFromBits(v.w[0]), canopyFloatFromBits(v.w[1]), canopyFloatFromBits(v.w[2])};
  const uint32_t level = v.w[3] & 0xFFu, cachedMax = (v.w[3] >> 8) & 0xFFu;
  if (cachedMax != maxLevel) return false;  // also where empty: maxLevel <= a model's depth < kNoLevel
  const float size = levelSize(level);
  float x[3] = {u.x, u.y, u.z};
  bool in = true;
  for (int a = 0; a < 3; ++a) {
    x[a] = x[a] < 0.0f ? 0.0f : (x[a] >= 1.0f ? 0.99999994f : x[a]);
    in = in && x[a] >= lo[a] && x[a] < lo[a] + size;
  }
  return in;
}

// A shading segment's light at unit point um (world ray parameter tm): the descent's light item and
// the node-local coordinates of um in it. Light pages are used and asked for here, only by
// segments with matter (not by empty space).
CANOPY_HD inline void segmentLight(const SceneView& s, const ModelView& m, const Descent& d, V3 um, float tm, Segment& g) {
  g.haarLocal = kHaarNone;
  g.haarItem = nullptr;
  if (s.shade.exactLight && m.haarLight && d.level == m.depth) {
    // --light exact, the finest level of a Haar-lit model: the chaar brick at the sample's lattice
    // point, if its page is resident (else it is asked for and the float16 items serve).
    const float rc = float(m.rootCells);
    const CanopyHaarLocation at =
        canopyHaarLocate(m.haar, um.x * rc - 0.5f + float(m.origin[0]), um.y * rc - 0.5f + float(m.origin[1]), um.z * rc - 0.5f + float(m.origin[2]));
    const int32_t slot = at.page != kCanopyNone ? s.pageSlot[at.page] : -1;
    if (at.page == kCanopyNone || slot >= 0) {
      if (slot >= 0) {
        writeStamp(s.slotUsed + slot, s.stamp);
        g.haarItem = canopyHaarItemInPage(s.pool + size_t(slot) * s.pageBytes, at.item);
      }
      g.haarLocal = uint32_t(at.at.lx) | uint32_t(at.at.ly) << 2 | uint32_t(at.at.lz) << 4 | m.haar.fp16 << 6;
      g.light[0] = at.at.fx, g.light[1] = at.at.fy, g.light[2] = at.at.fz;
      g.lightItem = nullptr;
      g.tSample = tm;
      return;
    }
    writeStamp(s.pageWanted + at.page, s.stamp);
  }
  if (d.missingLightPage != kCanopyNone) writeStamp(s.pageWanted + d.missingLightPage, s.stamp);
  g.lightItem = descentLightItem(s, d);
  g.tSample = tm;
  if (g.lightItem) {
    writeStamp(s.slotUsed + d.lightPoolSlot, s.stamp);
    float lo[3];
    const float inv = 1.0f / levelBox(d, d.lightLevel, lo);
    g.light[0] = (um.x - lo[0]) * inv;
    g.light[1] = (um.y - lo[1]) * inv;
    g.light[2] = (um.z - lo[2]) * inv;
  } else {
    if (d.coarsestLightPage != kCanopyNone) writeStamp(s.pageWanted + d.coarsestLightPage, s.stamp);
    g.light[0] = g.light[1] = g.light[2] = 0.0f;
  }
}

// The indirect light of a shading segment of instance `inst` on the ray o + t dir: the LB light of
// its light item, else the density-only ambient term; each term times its scene factor at its sample.
// kWithLight = false: compiled without the LB light code, for scenes without lit models (where no
// segment has a light item, so the result is the same).
template <bool kWithLight = true>
CANOPY_HD inline void segmentIndirect(const SceneView& s, const InstanceView& inst, const Segment& g, V3 o, V3 dir, float out[3]) {
  const SceneLightPair factor = sceneLightFactors(s.light, o + dir * g.tSample);
  if (kWithLight && g.haarLocal != kHaarNone) {
    haar::BrickLookup at;
    at.slot = 0;
    at.lx = int(g.haarLocal & 3u), at.ly = int((g.haarLocal >> 2) & 3u), at.lz = int((g.haarLocal >> 4) & 3u);
    at.fx = g.light[0], at.fy = g.light[1], at.fz = g.light[2];
    const haar::Rgb sun = {s.shade.sun[0], s.shade.sun[1], s.shade.sun[2]};
    sampleHaarLbLight(g.haarItem, (g.haarLocal >> 6) & 1u, at, inst.sunWeights, sun, s.shade.ambient, factor.sun, factor.ambient, out);
    return;
  }
  if (!kWithLight || !g.lightItem) {
    ambientOnly(s, factor, out);
    return;
  }
  sampleLbLight(g.lightItem, inst.sunWeights, g.light[0], g.light[1], g.light[2], s.shade.sun, s.shade.ambient, factor, out);
}

// An instance's segment that stays what it is (k = 0, the same end) over later steps: the primary
// march keeps it instead of evaluating the instance again at each step of its neighbours (another
// instance's brick steps, while this one crosses an empty node). instanceSegment() fills it for an
// EMPTY LEAF (no children, no brick, density 0), and for a run of empty cells of a brick (the
// argument is at that code, emptyRunEnd's use): evaluating the instance again at any t' with
//   t' < until   and   the footprint's level at t' >= level (the leaf's level)
// descends to the same leaf (the point is inside it, and a leaf ends every descent that reaches its
// level) and returns k = 0 with the same end, bit for bit: `until` stops 3 epsilons (instanceSegment's
// eps at the segment's end, which bounds the eps at t') short of the end, far more than the float
// rounding of the point (a few ulps of unit coordinates, < 1e-3 cell) and of the exit. Everything
// else (bricks, uniform nodes, misses, shadow cones) is evaluated at every step as before. The
// primary march then folds the level condition into `until` (levelHoldsUntil: the footprint only
// grows along the ray, so the level condition holds below some t), and a held hit costs one
// comparison per step.
struct EmptyHold {
  float until;     // -inf: nothing held
  float end;       // the held segment's end (its tEnd)
  uint32_t level;  // the leaf's level
};

// The end of the run of empty cells (formats/canopy_file.h, empty-cell masks) of a brick that
// the ray o + t d (unit space) crosses from unit point u on: false when u's cell is not empty, else
// true and tEnd = where the ray enters the first cell that is not, or leaves the brick ([brickLo,
// brickLo + brickSize), inv = 1 / brickSize). A 3D-DDA over the brick's n^3 cells; each plane's
// crossing is computed from the plane alone (as nodeExit does), so a walk that starts in a later
// cell of the same run ends at the same value.
CANOPY_HD inline bool emptyRunEnd(const uint64_t* mask, V3 uo, V3 ud, V3 u, const float brickLo[3], float brickSize, float inv, float& tEnd) {
  constexpr int n = int(kCanopyEmptyCells);
  const auto empty = [mask](int x, int y, int z) {
    const uint32_t i = uint32_t(x + n * (y + n * z));
    return ((mask[i / 64] >> (i % 64)) & 1u) != 0;
  };
  int j[3];
  for (int a = 0; a < 3; ++a) {
    const float q = floorf((comp(u, a) - brickLo[a]) * inv * float(n));
    j[a] = q < 0.0f ? 0 : (q > float(n - 1) ? n - 1 : int(q));
  }
  if (!empty(j[0], j[1], j[2])) return false;
  const float q = brickSize / float(n);
  float tn[3];
  int st[3];
  for (int a = 0; a < 3; ++a) {
    const float da = comp(ud, a);
    st[a] = fabsf(da) < 1e-30f ? 0 : (da > 0.0f ? 1 : -1);
    tn[a] = st[a] == 0 ? 3.0e38f : (brickLo[a] + float(j[a] + (st[a] > 0)) * q - comp(uo, a)) / da;
  }
  for (;;) {
    int a = tn[1] < tn[0] ? 1 : 0;
    a = tn[2] < tn[a] ? 2 : a;
    tEnd = tn[a];
    j[a] += st[a];
    if (st[a] == 0 || j[a] < 0 || j[a] > n - 1 || !empty(j[0], j[1], j[2])) return true;
    tn[a] = (brickLo[a] + float(j[a] + (st[a] > 0)) * q - comp(uo, a)) / comp(ud, a);
  }
}

// The octree level instanceSegment() picks for footprint (world) at instance `inst`.
CANOPY_HD CANOPY_FORCEINLINE uint32_t segmentLevel(const SceneView& s, const InstanceView& inst, uint32_t depth, float footprint) {
  return levelForFootprint(depth, footprint / inst.cellWorld, s.shade.lodBias);
}

// A ray parameter T such that the level of a primary cone (segmentLevel at footprint t *
// pixelAngle) is >= `level` at every t < T, so that a held segment's level condition (EmptyHold)
// can be folded into its `until` once, instead of being evaluated at every step. levelForFootprint
// gives depth - floor(log2 fp) + lodBias (fp = max(footprint / cellWorld, 1), clamped, truncated),
// which is >= level (level >= 1) exactly where floor(log2 fp) <= depth + lodBias - level, i.e.
// fp < 2^k with k = floor(depth + lodBias - level) + 1. T stops 1e-5 short of that relatively: far
// more than the rounding of t * pixelAngle / cellWorld and of log2f near 2^k (a few 1e-7), so
// every t < T has fp < 2^k in floats too. (k >= 1 wherever the hold was made: its level is at most
// the level at that t.) Level 0 holds everywhere.
CANOPY_HD inline float levelHoldsUntil(const SceneView& s, const InstanceView& inst, uint32_t depth, float pixelAngle, uint32_t level) {
  if (level == 0) return 3.0e38f;
  const float k = floorf(float(depth) + s.shade.lodBias - float(level)) + 1.0f;
  return ldexpf(inst.cellWorld / pixelAngle, int(k)) * 0.99999f;
}

// The segment of instance `inst` at ray position t (world), the cone footprint there being
// `footprint` (world units). tout is the end of the instance's box interval. `hold` (optional): set
// for an empty leaf's segment, else cleared (see EmptyHold).
CANOPY_HD inline Segment instanceSegment(const SceneView& s, const InstanceView& inst, V3 o, V3 dir, float t,
                                         float tout, float footprint, bool shading, DescentCache& cache,
                                         EmptyHold* hold = nullptr) {
  const ModelView& m = s.models[inst.model];
  const V3 uo = applyPoint(inst.worldToUnit, o);
  const V3 ud = applyVector(inst.worldToUnit, dir);
  const float cellsPerWorld = length(ud) * float(m.rootCells);
  // a thousandth of a cell, but at least a few float ulps of t (progress far from the origin)
  const float eps = fmaxf(1e-3f / cellsPerWorld, fabsf(t) * 1e-6f);
  const uint32_t level = segmentLevel(s, inst, m.depth, footprint);
  const V3 up = uo + ud * (t + eps);
  if (hold) hold->until = -3.0e38f;
  CANOPY_PLAY_COUNT(s, segments, 1);
  if (!s.shade.descentCache || !descentCovers(cache, up, level)) {
    cache.d = descendResident(s, m, up, level, shading);
    CANOPY_PLAY_COUNT(s, descents, 1);
  }
  const Descent& d = cache.d;
  Segment g;
  float tExit = nodeExit(uo, ud, d.lo, levelSize(d.level));
  if (tExit < t + eps) tExit = t + eps;
  if (d.missingPage != kCanopyNone) writeStamp(s.pageWanted + d.missingPage, s.stamp);
  const unsigned char* brickPage = descentBrickPage(s, d);
  const bool useBrick = d.node.brick != kCanopyNone && brickPage != nullptr;
  if (!useBrick) {
    // constant node, or a missing brick without a close resident ancestor: the node's mean
    const CanopySample c = canopyUnpack(d.node.density, d.node.material);
    g.k = s.shade.sigma * c.density * cellsPerWorld;
    g.albedo[0] = c.albedo[0], g.albedo[1] = c.albedo[1], g.albedo[2] = c.albedo[2];
    float tEnd = tExit;
    if (shading && c.density > 0.0f) {  // a shadow cone integrates it in one go
      const float maxLen = kMaxConstantCells / cellsPerWorld;
      tEnd = tEnd < t + maxLen ? tEnd : t + maxLen;
    }
    g.tEnd = tEnd < tout ? tEnd : tout;
    if (shading && g.k > 0.0f) segmentLight(s, m, d, uo + ud * (0.5f * (t + g.tEnd)), 0.5f * (t + g.tEnd), g);
    if (hold && c.density == 0.0f && d.node.brick == kCanopyNone && !(d.node.child != kCanopyNone && d.node.child < m.tileCount)) {
      const float epsEnd = fmaxf(1e-3f / cellsPerWorld, fabsf(g.tEnd) * 1e-6f);
      hold->until = g.tEnd - 3.0f * epsEnd;
      hold->end = g.tEnd;
      hold->level = d.level;
    }
    return g;
  }
  writeStamp(s.slotUsed + d.brickPoolSlot, s.stamp);
  float brickLo[3];
  const float brickSize = levelBox(d, d.brickLevel, brickLo);
  const float inv = 1.0f / brickSize;
  if (s.shade.skipEmptyBlocks && s.brickMaskOffset != 0) {
    const uint64_t* mask = reinterpret_cast<const uint64_t*>(brickPage + s.brickMaskOffset) + kCanopyEmptyWords * d.brickSlotInPage;
    float tEnd;
    if (emptyRunEnd(mask, uo, ud, up, brickLo, brickSize, inv, tEnd)) {
      // k = 0 up to the empty run's end: the samples a march would take there all read 0
      CANOPY_PLAY_COUNT(s, emptyBlockSkips, 1);
      tEnd = tEnd > t + eps ? tEnd : t + eps;
      tEnd = tEnd < tExit ? tEnd : tExit;
      g.tEnd = tEnd < tout ? tEnd : tout;
      g.k = 0.0f;
      g.albedo[0] = g.albedo[1] = g.albedo[2] = 0.0f;
      if (hold) {
        // Evaluated again at t' < until with the footprint's level still >= d.level (so equal to it
        // where the node has children: the level only gets coarser along the ray), the descent
        // reaches the same node and brick, the point lies in a later cell of the same run, and
        // the walk from there ends at the same plane, computed alike (the argument of EmptyHold;
        // where the ray grazes a cell edge within float rounding, the point's cell may
        // be the diagonal neighbour of the walk's, and the two could differ).
        const float epsEnd = fmaxf(1e-3f / cellsPerWorld, fabsf(g.tEnd) * 1e-6f);
        hold->until = g.tEnd - 3.0f * epsEnd;
        hold->end = g.tEnd;
        hold->level = d.level;
      }
      return g;
    }
  }
  CANOPY_PLAY_COUNT(s, brickSamples, 1);
  const float voxelCells = float(m.rootCells >> 3) * levelSize(d.level);  // this level's voxel, in cells
  float tEnd = t + s.shade.stepFactor * voxelCells / cellsPerWorld;
  tEnd = tEnd < tExit ? tEnd : tExit;
  tEnd = tEnd < tout ? tEnd : tout;
  const V3 um = uo + ud * (0.5f * (t + tEnd));
  const CanopySample c = canopySampleBrick(canopyBrickInPage(brickPage, d.brickSlotInPage), (um.x - brickLo[0]) * inv,
                                           (um.y - brickLo[1]) * inv, (um.z - brickLo[2]) * inv);
  g.k = s.shade.sigma * c.density * cellsPerWorld;
  if (c.density == 0.0f) CANOPY_PLAY_COUNT(s, zeroBrickSamples, 1);
  g.albedo[0] = c.albedo[0], g.albedo[1] = c.albedo[1], g.albedo[2] = c.albedo[2];
  g.tEnd = tEnd;
  if (shading && g.k > 0.0f) segmentLight(s, m, d, um, 0.5f * (t + tEnd), g);
  return g;
}

// ------------------------------------------------------------------------------------------------
// The lock-step march over every instance along a ray
// ------------------------------------------------------------------------------------------------
// The first 16 bytes are what every step reads of every hit (tin, hold.until, hold.end): one
// 16-byte load on the GPU (hitHead).
struct alignas(16) Hit {
  float tin;
  EmptyHold hold;  // primary march: its current empty leaf segment (until = -inf: none)
  uint32_t instance;
  float tout;
};
static_assert(offsetof(Hit, hold) == 4 && offsetof(EmptyHold, until) == 0 && offsetof(EmptyHold, end) == 4, "hitHead's layout");

// tin, hold.until and hold.end of a hit.
CANOPY_HD CANOPY_FORCEINLINE void hitHead(const Hit& h, float& tin, float& until, float& end) {
  const Words4 v = load16(&h);
  tin = canopyFloatFromBits(v.w[0]), until = canopyFloatFromBits(v.w[1]), end = canopyFloatFromBits(v.w[2]);
}

// 3D-DDA over the instance grid plus the hit list. The hits live in fixed slots (a bit of `live`
// each, visited in ascending slot order): a hit never moves, its descent cache sits beside it at
// the same index, and retiring one clears a bit instead of shifting the hits after it (local
// memory on the GPU). Retiring runs only once the march reaches the nearest exit (`minTout`), not
// at every step.
// A cell entered through a face adds only the instances that the cell behind the face does not
// list (SceneView::gridFaceItems): every other one was met in an earlier cell of the walk, and its
// interval along the ray, tested there, was added then or rejected for good (a rejection at an
// earlier, smaller tNow holds at a later one). An instance's cells form a box of cells and the
// walk's cells move monotonically along each axis, so an instance met in any earlier cell is
// listed by the cell just behind. So no membership scan is needed, except after a hit was dropped
// from a full list (`dropped`): from then on each cell's whole list is scanned against the hits,
// as a dropped instance is found again from a later cell it overlaps.
struct InstanceWalk {
  Hit hits[kHitCapacity];
  DescentCache caches[kHitCapacity];  // caches[i]: hits[i]'s last descent along the ray (empty when added)
  uint32_t live;                      // bit i: hits[i] is pending or active
  float minTout;                      // <= every live hit's tout
  int cell[3];
  int stepDir[3];
  float tNext[3], tDelta[3];
  float tCellExit;  // the march may advance up to here with the current list
  float tGridExit;
  bool done;
  bool dropped;  // a hit was dropped from a full list: cells add their whole lists with a membership scan
};
constexpr uint32_t kAllHitSlots = kHitCapacity >= 32 ? 0xFFFFFFFFu : (1u << kHitCapacity) - 1u;

// Index of the lowest set bit of a non-zero mask.
CANOPY_HD CANOPY_FORCEINLINE uint32_t lowestSetBit(uint32_t m) {
#if defined(__CUDA_ARCH__)
  return uint32_t(__ffs(int(m)) - 1);
#else
  return uint32_t(__builtin_ctz(m));
#endif
}

// Adds the instances of the current cell, entered through `face` (2 a for a step along +a, 2 a + 1
// along -a; -1: the walk's first cell).
CANOPY_HD inline void walkAddCell(const SceneView& s, InstanceWalk& w, V3 o, V3 d, float tNow, int face) {
  const int c = w.cell[0] + s.gridDim[0] * (w.cell[1] + s.gridDim[1] * w.cell[2]);
  const bool scan = face < 0 || w.dropped;
  const uint32_t* items = scan ? s.gridItems : s.gridFaceItems;
  const uint32_t list = scan ? uint32_t(c) : uint32_t(6 * c + face);
  const uint32_t* start = scan ? s.gridStart : s.gridFaceStart;
  const uint32_t kEnd = start[list + 1];
  for (uint32_t k = start[list]; k < kEnd; ++k) {
    const uint32_t id = items[k];
    if (scan) {
      bool present = false;
      for (uint32_t m = w.live; m != 0; m &= m - 1u) present |= w.hits[lowestSetBit(m)].instance == id;
      if (present) continue;
    }
    const InstanceView& inst = s.instances[id];
    // the exact interval: the ray against the box of the model's matter in the instance's unit
    // space (an oriented box in world space; t is the same parameter in both spaces)
    float t0, t1;
    rayBox(applyPoint(inst.worldToUnit, o), applyVector(inst.worldToUnit, d), v3(inst.unitLo[0], inst.unitLo[1], inst.unitLo[2]),
           v3(inst.unitHi[0], inst.unitHi[1], inst.unitHi[2]), t0, t1);
    if (t0 < tNow) t0 = tNow;
    if (!(t1 > t0)) continue;
    uint32_t slot;
    if (w.live == kAllHitSlots) {  // full: replace the farthest pending hit if this one is nearer
      slot = 0;
      for (uint32_t m = w.live & (w.live - 1u); m != 0; m &= m - 1u) {
        const uint32_t h = lowestSetBit(m);
        slot = w.hits[h].tin > w.hits[slot].tin ? h : slot;
      }
      w.dropped = true;  // this one or the farthest: found again from a later cell it overlaps
      CANOPY_PLAY_COUNT(s, hitDrops, 1);
      if (w.hits[slot].tin <= t0) continue;
    } else {
      slot = lowestSetBit(~w.live & kAllHitSlots);
      w.live |= 1u << slot;
    }
    w.hits[slot] = Hit{t0, EmptyHold{-3.0e38f, 0.0f, 0u}, id, t1};
    w.caches[slot].d.maxLevel = kNoLevel;
    w.minTout = t1 < w.minTout ? t1 : w.minTout;
  }
}

// Starts the walk for the ray o + t d, t in [tStart, tEnd].
CANOPY_HD inline void walkBegin(const SceneView& s, InstanceWalk& w, V3 o, V3 d, float tStart, float tEnd) {
  w.live = 0;
  w.minTout = 3.0e38f;
  w.done = true;
  w.dropped = false;
  w.tCellExit = tEnd;
  if (s.instanceCount == 0) return;
  const V3 lo = v3(s.gridLo[0], s.gridLo[1], s.gridLo[2]);
  const V3 hi = v3(s.gridLo[0] + s.gridCell[0] * float(s.gridDim[0]), s.gridLo[1] + s.gridCell[1] * float(s.gridDim[1]),
                   s.gridLo[2] + s.gridCell[2] * float(s.gridDim[2]));
  float t0, t1;
  rayBox(o, d, lo, hi, t0, t1);
  t0 = t0 > tStart ? t0 : tStart;
  t1 = t1 < tEnd ? t1 : tEnd;
  if (!(t1 > t0)) return;
  w.done = false;
  w.tGridExit = t1;
  const V3 p = o + d * t0;
  for (int a = 0; a < 3; ++a) {
    const float cs = s.gridCell[a];
    int c = int(floorf((comp(p, a) - s.gridLo[a]) / cs));
    c = c < 0 ? 0 : (c >= s.gridDim[a] ? s.gridDim[a] - 1 : c);
    w.cell[a] = c;
    const float da = comp(d, a);
    if (da > 0.0f) {
      w.stepDir[a] = 1;
      w.tNext[a] = (s.gridLo[a] + float(c + 1) * cs - comp(o, a)) / da;
      w.tDelta[a] = cs / da;
    } else if (da < 0.0f) {
      w.stepDir[a] = -1;
      w.tNext[a] = (s.gridLo[a] + float(c) * cs - comp(o, a)) / da;
      w.tDelta[a] = -cs / da;
    } else {
      w.stepDir[a] = 0;
      w.tNext[a] = 3.0e38f;
      w.tDelta[a] = 3.0e38f;
    }
  }
  walkAddCell(s, w, o, d, t0, -1);
  float tx = w.tNext[0] < w.tNext[1] ? w.tNext[0] : w.tNext[1];
  tx = tx < w.tNext[2] ? tx : w.tNext[2];
  w.tCellExit = tx < t1 ? tx : t1;
}

// Advances the DDA one cell (when the march reached tCellExit).
CANOPY_HD inline void walkAdvance(const SceneView& s, InstanceWalk& w, V3 o, V3 d, float tNow) {
  if (w.done) return;
  if (w.tCellExit >= w.tGridExit) {
    w.done = true;
    return;
  }
  int a = 0;
  if (w.tNext[1] < w.tNext[a]) a = 1;
  if (w.tNext[2] < w.tNext[a]) a = 2;
  w.cell[a] += w.stepDir[a];
  w.tNext[a] += w.tDelta[a];
  if (w.cell[a] < 0 || w.cell[a] >= s.gridDim[a]) {
    w.done = true;
    w.tCellExit = w.tGridExit;
    return;
  }
  walkAddCell(s, w, o, d, tNow, 2 * a + (w.stepDir[a] > 0 ? 0 : 1));
  float tx = w.tNext[0] < w.tNext[1] ? w.tNext[0] : w.tNext[1];
  tx = tx < w.tNext[2] ? tx : w.tNext[2];
  w.tCellExit = tx < w.tGridExit ? tx : w.tGridExit;
}

// Drops hits that ended before t (tout <= t); nothing to do before the nearest exit.
CANOPY_HD inline void walkRetire(InstanceWalk& w, float t) {
  if (t < w.minTout) return;
  w.minTout = 3.0e38f;
  for (uint32_t m = w.live; m != 0; m &= m - 1u) {
    const uint32_t h = lowestSetBit(m);
    const float tout = w.hits[h].tout;
    if (!(tout > t)) {
      w.live &= ~(1u << h);
      continue;
    }
    w.minTout = tout < w.minTout ? tout : w.minTout;
  }
}

// ------------------------------------------------------------------------------------------------
// The sun transmittance map (kShadowsMap)
// ------------------------------------------------------------------------------------------------
// Two grids. (1) The scene's EXTINCTION GRID (world axes, built once per scene by the backend):
// at each voxel centre the sum, over the instances whose lattice box holds the point (found
// through the instance grid), of sigma x the node mean density / the instance's cell, the node
// being the one of edge <= 2 voxels on the descent (node tiles are always resident, so the grid
// needs no page, is the same for every cache state and is ready at the first frame). (2) The
// frame's TRANSMITTANCE MAP (light space, per render pass): each column is a ray from the sun,
// marched front to back through the extinction grid (trilinear, steps of at most one extinction
// voxel); T at a voxel centre = exp(-optical depth from the sun). A sample reads T trilinearly.
// The cost per frame is one march per map column (independent of the image and of the number of
// samples) and 8 reads per shaded sample, instead of a shadow cone through every instance per
// shadow interval. Shadows are resolved to about one finest node (8 lattice cells) and the map
// voxel; the cone mode (kShadowsCone) keeps the brick-resolution reference.
struct ExtinctionGridView {
  float* k;           // dim[0] * dim[1] * dim[2] values, x fastest (extinction per world unit)
  float lo[3];        // world position of voxel (0, 0, 0)'s centre
  float voxel;        // voxel edge (world)
  int32_t dim[3];
};

// The node-mean extinction of every instance at world point x (per world unit), nodes of edge at
// most `maxNode` (world).
CANOPY_HD inline float sceneMeanExtinctionAt(const SceneView& s, V3 x, float maxNode) {
  if (s.instanceCount == 0) return 0.0f;
  int c[3];
  for (int a = 0; a < 3; ++a) {
    const float g = (comp(x, a) - s.gridLo[a]) / s.gridCell[a];
    if (!(g >= 0.0f) || g >= float(s.gridDim[a])) return 0.0f;  // outside every instance box
    c[a] = int(g);
  }
  const int cell = c[0] + s.gridDim[0] * (c[1] + s.gridDim[1] * c[2]);
  float k = 0.0f;
  for (uint32_t it = s.gridStart[cell]; it < s.gridStart[cell + 1]; ++it) {
    const InstanceView& inst = s.instances[s.gridItems[it]];
    const V3 u = applyPoint(inst.worldToUnit, x);
    if (u.x < inst.unitLo[0] || u.y < inst.unitLo[1] || u.z < inst.unitLo[2] || !(u.x < inst.unitHi[0]) ||
        !(u.y < inst.unitHi[1]) || !(u.z < inst.unitHi[2]))
      continue;
    const ModelView& m = s.models[inst.model];
    // the finest level whose node edge (rootCells 2^-L cells) is at most maxNode
    const float rootWorld = float(m.rootCells) * inst.cellWorld;
    const float L = ceilf(log2f(rootWorld / maxNode));
    const uint32_t level = L <= 0.0f ? 0u : (L >= float(m.depth) ? m.depth : uint32_t(L));
    const CanopyLookup n = canopyDescend(m.tiles, m.tileCount, m.root, m.depth, u.x, u.y, u.z, level);
    k += s.shade.sigma * canopyUnpack(n.node.density, n.node.material).density / inst.cellWorld;
  }
  return k;
}

// The extinction grid's voxel i (x fastest): the mean of 2x2x2 samples at +-voxel/4 about its
// centre (a box filter, so that a face of matter that falls on a voxel centre keeps its mass once
// the grid is read trilinearly).
CANOPY_HD inline void buildExtinctionVoxel(const SceneView& s, const ExtinctionGridView& g, int64_t i) {
  const int x = int(i % g.dim[0]);
  const int y = int((i / g.dim[0]) % g.dim[1]);
  const int z = int(i / (int64_t(g.dim[0]) * g.dim[1]));
  const V3 c = v3(g.lo[0] + float(x) * g.voxel, g.lo[1] + float(y) * g.voxel, g.lo[2] + float(z) * g.voxel);
  const float q = 0.25f * g.voxel;
  float k = 0.0f;
  for (int j = 0; j < 8; ++j)
    k += sceneMeanExtinctionAt(s, c + v3((j & 1) ? q : -q, (j & 2) ? q : -q, (j & 4) ? q : -q), 2.0f * g.voxel);
  g.k[i] = 0.125f * k;
}

// Trilinear extinction at world point p (0 outside the grid, whose border voxels are empty).
CANOPY_HD inline float extinctionAt(const ExtinctionGridView& g, V3 p) {
  const float inv = 1.0f / g.voxel;
  int i0[3];
  float f[3];
  for (int a = 0; a < 3; ++a) {
    const float x = (comp(p, a) - g.lo[a]) * inv;
    if (!(x >= 0.0f) || !(x < float(g.dim[a] - 1))) return 0.0f;
    const float fl = floorf(x);
    i0[a] = int(fl);
    f[a] = x - fl;
  }
  const int64_t sy = g.dim[0], sz = int64_t(g.dim[0]) * g.dim[1];
  const float* b = g.k + i0[0] + sy * i0[1] + sz * i0[2];
  const float c00 = b[0] + (b[1] - b[0]) * f[0];
  const float c10 = b[sy] + (b[sy + 1] - b[sy]) * f[0];
  const float c01 = b[sz] + (b[sz + 1] - b[sz]) * f[0];
  const float c11 = b[sz + sy] + (b[sz + sy + 1] - b[sz + sy]) * f[0];
  const float c0 = c00 + (c10 - c00) * f[1];
  const float c1 = c01 + (c11 - c01) * f[1];
  return c0 + (c1 - c0) * f[2];
}

// The world point of map voxel (u, v, w)'s centre.
CANOPY_HD CANOPY_FORCEINLINE V3 shadowMapPoint(const ShadowMapView& m, float u, float v, float w) {
  return m.origin + m.axis[0] * (u * m.voxel) + m.axis[1] * (v * m.voxel) + m.axis[2] * (w * m.voxel);
}

// Map column c = u + dim0 v: marched front to back from the sun through the extinction grid, T
// stored at each voxel centre; between two centres `sub` midpoint steps (voxel 0 lies outside the
// scene's box, so its T is 1).
CANOPY_HD inline void buildShadowMapColumn(const ShadowMapView& m, const ExtinctionGridView& g, int sub, int64_t c) {
  const int u = int(c % m.dim[0]), v = int(c / m.dim[0]);
  const int64_t stride = int64_t(m.dim[0]) * m.dim[1];
  const float ds = m.voxel / float(sub);
  const V3 step = m.axis[2] * ds;
  V3 p = shadowMapPoint(m, float(u), float(v), 0.0f) + step * 0.5f;
  float tau = 0.0f;  // optical depth from the sun to the current voxel centre
  for (int w = 0; w < m.dim[2]; ++w) {
    m.T[c + stride * w] = expf(-tau);
    for (int j = 0; j < sub; ++j, p = p + step) tau += extinctionAt(g, p) * ds;
  }
}

// Tshadow at world point p: trilinear in the map (clamped to its box, whose border voxels are
// empty: outside it the value is 1), read at p moved `bias` towards the sun. The map spreads each
// node's matter over about a node and a voxel in every direction, so without the bias a sample
// near a crown's sunlit surface would be shadowed by matter that lies behind it (away from the
// sun), by an amount that depends on where the sample falls between the map's voxel centres:
// banding ("shadow acne"). The price is that matter within `bias` of the sample towards the sun
// does not shadow it.
CANOPY_HD inline float shadowMapLookup(const ShadowMapView& m, V3 p) {
  const V3 q = p - m.axis[2] * m.bias - m.origin;
  const float inv = 1.0f / m.voxel;
  int i0[3];
  float f[3];
  for (int a = 0; a < 3; ++a) {
    float x = dot(q, m.axis[a]) * inv;
    const float hi = float(m.dim[a] - 1);
    x = x > 0.0f ? x : 0.0f;
    x = x < hi ? x : hi;
    const float fl = floorf(x);
    i0[a] = int(fl);
    f[a] = x - fl;
    if (i0[a] >= m.dim[a] - 1) {
      i0[a] = m.dim[a] > 1 ? m.dim[a] - 2 : 0;
      f[a] = m.dim[a] > 1 ? 1.0f : 0.0f;
    }
  }
  const int64_t sx = 1, sy = m.dim[0], sz = int64_t(m.dim[0]) * m.dim[1];
  const float* b = m.T + i0[0] + sy * i0[1] + sz * i0[2];
  const int64_t dx = m.dim[0] > 1 ? sx : 0, dy = m.dim[1] > 1 ? sy : 0, dz = m.dim[2] > 1 ? sz : 0;
  const float c00 = b[0] + (b[dx] - b[0]) * f[0];
  const float c10 = b[dy] + (b[dy + dx] - b[dy]) * f[0];
  const float c01 = b[dz] + (b[dz + dx] - b[dz]) * f[0];
  const float c11 = b[dz + dy] + (b[dz + dy + dx] - b[dz + dy]) * f[0];
  const float c0 = c00 + (c10 - c00) * f[1];
  const float c1 = c01 + (c11 - c01) * f[1];
  return c0 + (c1 - c0) * f[2];
}

struct ConeResult {
  float rgb[3];           // premultiplied radiance
  float transmittance;
  // kWithDepth only: sums over the shaded samples of w, w / t and w / t^2, w = T alpha (a sample's
  // share of the pixel): the moments of the inverse depth that stereo reprojection needs
  // (pixelDisparity, stereo.h).
  float depthSums[3];
};

// Transmittance from p towards the sun (shadow cone, footprint starts at `footprint0`).
CANOPY_HD inline float shadowTransmittance(const SceneView& s, V3 p, float footprint0) {
  const V3 d = s.shade.toSun;
  CANOPY_PLAY_COUNT(s, shadowCones, 1);
  InstanceWalk w;
  walkBegin(s, w, p, d, 0.0f, 3.0e38f);
  float T = 1.0f;
  float t = 0.0f;
  while (true) {
    walkRetire(w, t);
    if (w.live == 0 && w.done) break;
    float next = w.done ? 3.0e38f : w.tCellExit;
    float k = 0.0f;
    bool active = false;
    for (uint32_t m = w.live; m != 0; m &= m - 1u) {
      const uint32_t h = lowestSetBit(m);
      const Hit& hit = w.hits[h];
      if (hit.tin > t) {
        next = hit.tin < next ? hit.tin : next;
        continue;
      }
      active = true;
      const Segment g =
          instanceSegment(s, s.instances[hit.instance], p, d, t, hit.tout, footprint0 + t * s.shade.shadowAperture, false, w.caches[h]);
      k += g.k;
      next = g.tEnd < next ? g.tEnd : next;
    }
    if (!active && w.live == 0 && !w.done) {  // nothing here: skip to the next grid cell
      t = w.tCellExit;
      walkAdvance(s, w, p, d, t);
      continue;
    }
    if (next >= 3.0e38f) break;
    CANOPY_PLAY_COUNT(s, shadowSteps, 1);
    T *= expf(-k * (next - t));
    t = next;
    if (T < kShadowStopT) return 0.0f;
    while (!w.done && t >= w.tCellExit) walkAdvance(s, w, p, d, t);
  }
  return T;
}

// The ground's radiance at its point p, in the units of the foliage's shading (sampleShade: albedo x
// (sun x Tshadow + indirect)): a Lambertian plane with normal +Y,
//   albedo x (direct sun x max(0, toSun.y) x Tshadow(p) + ambient x the scene lattice's ambient factor at p).
// Tshadow as the foliage's (the frame's shadow map, a shadow cone with kWithCones, or 1 without
// shadows), so crowns cast their shadows on it; the scene lattice (lbsolve --scene, 1 = open sky)
// darkens the sky light under crowns; without one that factor is 1. The light that foliage
// scatters down onto the ground is not modelled.
template <bool kWithCones>
CANOPY_HD inline void groundRadiance(const SceneView& s, V3 p, float footprint, float out[3]) {
  const float cosSun = s.shade.toSun.y > 0.0f ? s.shade.toSun.y : 0.0f;
  float sunT = 1.0f;
  if (cosSun > 0.0f) {
    if (s.shade.shadows == kShadowsMap) {
      sunT = shadowMapLookup(s.shadowMap, p);
      CANOPY_PLAY_COUNT(s, shadowMapLookups, 1);
    } else if (kWithCones && s.shade.shadows == kShadowsCone) {
      sunT = shadowTransmittance(s, p, footprint);
    }
  }
  const float sky = s.shade.ambient * sceneLightFactors(s.light, p).ambient;
  for (int c = 0; c < 3; ++c) out[c] = s.shade.groundAlbedo[c] * (s.shade.direct[c] * cosSun * sunT + sky);
}

// Where the ray o + t d (t > 0) meets the ground from above; 3e38 where it does not (no ground, a ray
// level or rising, an eye on or below the plane: the ground is seen from above only).
CANOPY_HD inline float groundHit(const ShadeParams& shade, V3 o, V3 d) {
  if (!shade.ground || !(d.y < 0.0f) || !(o.y > shade.groundY)) return 3.0e38f;
  return (shade.groundY - o.y) / d.y;
}

// One primary cone: origin o, unit direction d, footprint(t) = footprint0 + t * pixelAngle.
// kWithCones: compiled with the shadow-cone path (kShadowsCone); without it that mode is treated
// as kShadowsOff, so the CUDA kernel of the other modes carries neither the shadow cone's instance
// walk (its hit list and descent caches in local memory) nor its registers. Same code otherwise.
// kWithDepth: also sums the inverse-depth moments of the shaded samples (ConeResult::depthSums).
// A ray that meets the ground (groundHit) before tMax is marched up to it (the parts of instances
// below the plane are cut) and ends there: what is left of its transmittance shows the ground
// (groundRadiance), and the result is opaque.
template <bool kWithCones, bool kWithLight = true, bool kWithDepth = false>
CANOPY_HD inline ConeResult traceCone(const SceneView& s, V3 o, V3 d, float pixelAngle, float tMax) {
  ConeResult r;
  r.rgb[0] = r.rgb[1] = r.rgb[2] = 0.0f;
  r.transmittance = 1.0f;
  r.depthSums[0] = r.depthSums[1] = r.depthSums[2] = 0.0f;
  CANOPY_PLAY_COUNT(s, cones, 1);
  const float tGround = groundHit(s.shade, o, d);
  const bool ground = tGround < tMax;
  if (ground) tMax = tGround;
  InstanceWalk w;
  walkBegin(s, w, o, d, 0.0f, tMax);
  float t = 0.0f;
  float T = 1.0f;
  float sunT = 1.0f, shadowT = -3.0e38f, shadowSpacing = 0.0f, shadowRefT = 2.0f;
  while (true) {
    walkRetire(w, t);
    if (w.live == 0 && w.done) break;
    float next = w.done ? tMax : w.tCellExit;
    // Each segment with matter is shaded as it is found, into two sums over the segments: its
    // extinction x albedo (which the step's sun transmittance will scale) and that times its
    // indirect light (which depends on the segment alone: its light is sampled at its own point).
    // No per-hit segment array is kept for a second pass (it was 16 x 64 bytes of local memory
    // written at every step).
    float k = 0.0f, kAlbedo[3] = {0.0f, 0.0f, 0.0f}, kIndirect[3] = {0.0f, 0.0f, 0.0f};
    bool active = false;
    const float footprint = t * pixelAngle;
    float minCell = 3.0e38f;
    // Two passes over the hits. The first is cheap (pending hits and held empty segments only bound
    // the step) and notes which hits must be evaluated; the second evaluates them, in the same
    // ascending order, so the sums are the same bit for bit. On the GPU this is what lets a warp
    // run instanceSegment() once for all its lanes: in one loop doing both, a lane that evaluates
    // its first hit and a lane that evaluates its third ran the evaluation at different iterations,
    // one after the other (docs/performance.md, 'Warp-uniform evaluation').
    uint32_t evaluate = 0;
    for (uint32_t m = w.live; m != 0; m &= m - 1u) {
      const uint32_t h = lowestSetBit(m);
      float tin, until, end;
      hitHead(w.hits[h], tin, until, end);
      // pending (tin > t): bounds the step by tin; held (the same empty segment as at the previous
      // step, EmptyHold; `until` includes the level condition, levelHoldsUntil): k = 0 up to its
      // end; else evaluated below. Without branches: a warp's lanes stay together here.
      const bool pending = tin > t;
      const bool held = !pending && t < until;
      const float bound = pending ? tin : end;
      next = (pending || held) && bound < next ? bound : next;
      active = active || !pending;
      evaluate |= uint32_t(!pending && !held) << h;
      CANOPY_PLAY_COUNT(s, heldSegments, held ? 1 : 0);
      if (kWithCones && !pending) {  // the shadow interval's length (below)
        const float cell = s.instances[w.hits[h].instance].cellWorld;
        minCell = cell < minCell ? cell : minCell;
      }
    }
    while (evaluate != 0) {
      const uint32_t h = lowestSetBit(evaluate);
      evaluate &= evaluate - 1u;
      Hit& hit = w.hits[h];
      const InstanceView& inst = s.instances[hit.instance];
      const Segment g = instanceSegment(s, inst, o, d, t, hit.tout, footprint, true, w.caches[h],
                                        s.shade.holdEmpty ? &hit.hold : nullptr);
      if (hit.hold.until > t) {  // a new hold: its level condition becomes a bound on t
        const float limit = levelHoldsUntil(s, inst, s.models[inst.model].depth, pixelAngle, hit.hold.level);
        hit.hold.until = limit < hit.hold.until ? limit : hit.hold.until;
      }
      next = g.tEnd < next ? g.tEnd : next;
      if (g.k <= 0.0f) continue;
      k += g.k;
      float ind[3];
      segmentIndirect<kWithLight>(s, inst, g, o, d, ind);
      for (int c = 0; c < 3; ++c) {
        const float ka = g.k * g.albedo[c];
        kAlbedo[c] += ka;
        kIndirect[c] += ka * ind[c];
      }
    }
    if (!active && w.live == 0) {
      if (w.done) break;
      t = w.tCellExit;
      walkAdvance(s, w, o, d, t);
      continue;
    }
    if (next > tMax) next = tMax;
    CANOPY_PLAY_COUNT(s, primarySteps, 1);
    if (k == 0.0f) CANOPY_PLAY_COUNT(s, emptySteps, 1);
    const float dt = next - t;
    const float alpha = 1.0f - expf(-k * dt);
    if (alpha > 0.0f && T * alpha > kMinContribution) {
      const float tm = t + 0.5f * dt;
      const V3 p = o + d * tm;
      CANOPY_PLAY_COUNT(s, shadedSamples, 1);
      if (s.shade.shadows == kShadowsMap) {
        sunT = shadowMapLookup(s.shadowMap, p);
        CANOPY_PLAY_COUNT(s, shadowMapLookups, 1);
      } else if (kWithCones && s.shade.shadows == kShadowsCone &&
                 (!(tm - shadowT < shadowSpacing) || T < kShadowReuseT * shadowRefT)) {
        // One shadow cone per shadow interval: samples closer than about a voxel (1.5 cells of the
        // nearest active instance, or two footprints) to the last shadow origin reuse its value,
        // unless the primary ray has since crossed matter of optical depth 0.051 (its T fell by 5 %):
        // a dense interval's deeper samples are darker than its first. (Reusing over the whole interval
        // made the direct sun 25-31 % too bright on a 40^3 oak against the path tracer,
        // docs/validation.md.)
        sunT = shadowTransmittance(s, p, footprint);
        shadowT = tm;
        shadowRefT = T;
        shadowSpacing = 2.0f * footprint > 1.5f * minCell ? 2.0f * footprint : 1.5f * minCell;
      }
      const float scale = T * alpha / k;
      for (int c = 0; c < 3; ++c) r.rgb[c] += scale * (kAlbedo[c] * s.shade.direct[c] * sunT + kIndirect[c]);
      if (kWithDepth) {
        const float w = T * alpha, inv = 1.0f / tm;
        r.depthSums[0] += w;
        r.depthSums[1] += w * inv;
        r.depthSums[2] += w * inv * inv;
      }
    }
    T *= 1.0f - alpha;
    t = next;
    if (T < s.shade.stopT || t >= tMax) break;
    while (!w.done && t >= w.tCellExit) walkAdvance(s, w, o, d, t);
  }
  if (ground) {
    float g[3];
    groundRadiance<kWithCones>(s, o + d * tGround, tGround * pixelAngle, g);
    for (int c = 0; c < 3; ++c) r.rgb[c] += T * g[c];
    if (kWithDepth) {
      const float inv = 1.0f / tGround;
      r.depthSums[0] += T;
      r.depthSums[1] += T * inv;
      r.depthSums[2] += T * inv * inv;
    }
    T = 0.0f;
  }
  r.transmittance = T;
  return r;
}

// ------------------------------------------------------------------------------------------------
// Camera
// ------------------------------------------------------------------------------------------------
struct CameraView {
  V3 position, forward, right, up;  // orthonormal; right/up scaled by tan(fov/2) (and aspect)
  float pixelAngle;                 // cone aperture per pixel (radians, small-angle)
  int width, height;
};

// The ray through pixel (x, y) (y = 0 the top row), through the pixel centre.
CANOPY_HD inline V3 cameraRay(const CameraView& c, int x, int y, float& footprintPerT) {
  const float sx = (2.0f * (float(x) + 0.5f) / float(c.width) - 1.0f);
  const float sy = (1.0f - 2.0f * (float(y) + 0.5f) / float(c.height));
  const V3 d = c.forward + c.right * sx + c.up * sy;
  const float len = length(d);
  footprintPerT = c.pixelAngle / len;  // off-axis pixels subtend slightly less
  return d * (1.0f / len);
}

// The disparity of a pixel's content between two parallel eyes: a point at depth z (along the view
// axis) moves by disparityScale / z pixels between them, disparityScale = eye separation x focal
// length in pixels. From the sums of w, w / t and w / t^2 over the pixel's samples (depthSums) and
// the ray's cosine to the view axis (z = t cos): out[0] = the w-weighted mean disparity, out[1] =
// its standard deviation, the spread of the pixel's content in disparity. No sample: 0, 0 (the
// sky, infinitely far).
CANOPY_HD inline void pixelDisparity(const float sums[3], float cosAxis, float disparityScale, float out[2]) {
  if (!(sums[0] > 0.0f)) {
    out[0] = out[1] = 0.0f;
    return;
  }
  const float k = disparityScale / cosAxis;
  const float m1 = sums[1] / sums[0], m2 = sums[2] / sums[0];
  const float var = m2 - m1 * m1;
  out[0] = k * m1;
  out[1] = k * sqrtf(var > 0.0f ? var : 0.0f);
}

// Renders pixel i of the frame into rgba (premultiplied RGB, alpha = 1 - T). kWithCones must be
// true when s.shade.shadows == kShadowsCone, kWithLight when s.litModels > 0 (renderPixel() picks
// them; the CUDA backend launches the kernel of the mode and scene). kWithDepth: also writes the
// pixel's disparity statistics for stereo reprojection into depth[2 i], depth[2 i + 1]
// (pixelDisparity: mean and spread, in pixels, for an eye separation of disparityScale / focal).
template <bool kWithCones, bool kWithLight, bool kWithDepth = false>
CANOPY_HD inline void renderPixelT(const SceneView& s, const CameraView& c, int64_t i, float* rgba, float* depth = nullptr,
                                   float disparityScale = 0.0f) {
  const int x = int(i % c.width), y = int(i / c.width);
  float fpPerT;
  const V3 d = cameraRay(c, x, y, fpPerT);
  const ConeResult r = traceCone<kWithCones, kWithLight, kWithDepth>(s, c.position, d, fpPerT, 3.0e37f);
  rgba[4 * i + 0] = r.rgb[0];
  rgba[4 * i + 1] = r.rgb[1];
  rgba[4 * i + 2] = r.rgb[2];
  rgba[4 * i + 3] = 1.0f - r.transmittance;
  if (kWithDepth) pixelDisparity(r.depthSums, dot(d, c.forward), disparityScale, depth + 2 * i);
}

// renderPixelT of the mode and scene (s.shade.shadows, s.litModels), with depth when `depth` is set.
CANOPY_HD inline void renderPixel(const SceneView& s, const CameraView& c, int64_t i, float* rgba, float* depth = nullptr,
                                  float disparityScale = 0.0f) {
  const bool cones = s.shade.shadows == kShadowsCone, light = s.litModels > 0;
  if (depth) {
    if (cones)
      light ? renderPixelT<true, true, true>(s, c, i, rgba, depth, disparityScale) : renderPixelT<true, false, true>(s, c, i, rgba, depth, disparityScale);
    else
      light ? renderPixelT<false, true, true>(s, c, i, rgba, depth, disparityScale) : renderPixelT<false, false, true>(s, c, i, rgba, depth, disparityScale);
  } else if (cones) {
    light ? renderPixelT<true, true>(s, c, i, rgba) : renderPixelT<true, false>(s, c, i, rgba);
  } else {
    light ? renderPixelT<false, true>(s, c, i, rgba) : renderPixelT<false, false>(s, c, i, rgba);
  }
}

}  // namespace canopy::play
