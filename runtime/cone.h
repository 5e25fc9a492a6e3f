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
//      constant node always uses its nearest brick ancestor's, as canopy_layout.h says); the node's
//      own light page is asked for when it is missing. Only when no light page on the path is
//      resident yet (a cold start) does the sample get the density-only indirect term
//      (ambient x ambient scene factor), and the coarsest brick's light page is asked for as well.
//      With --light exact (ShadeParams::exactLight), a segment at the finest level of a model that
//      has Haar light (format 1.1) samples the .chaar's brick at its lattice point instead
//      (segmentLight, sampleHaarLbLight), its Haar page used or asked for through the same cache.
//
// The code is in parts, each including the one before it (this file includes them all):
//   cone_math.h     small vector math, the ray/box test, division by a run-time constant
//   scene_view.h    the scene as the kernel sees it, ShadeParams, the CPU's work counters
//   cone_light.h    the LB light of a sample and the coarse scene lattice's factors (7.)
//   grid_dda.h      the 3D-DDA that the instance grid's walk and the empty-cell runs share
//   cone_segment.h  one instance's segment: the footprint's level, the descent, held segments (3.)
//   cone_walk.h     the walk of the instance grid and the hit list of the lock-step march (1., 2.)
//   shadow_map.h    the scene's extinction grid and the frame's sun transmittance map (5.)
//   cone.h          shadow cones, the ground, the primary cone (4.-5.), the camera, a pixel
#pragma once
#include "runtime/shadow_map.h"

namespace canopy::play {

struct ConeResult {
  float rgb[3];           // premultiplied radiance
  float transmittance;
  // kWithDepth only: sums over the shaded samples of w, w / t and w / t^2, w = T alpha (a sample's
  // share of the pixel): the moments of the inverse depth that stereo reprojection needs
  // (pixelDisparity, stereo.h).
  float depthSums[3];
  // kWithDepth only: the front layer, the samples from the first one on while their inverse depth
  // stays within the layer window of the first one of weight kLayerOpenWeight or more (frontLimit;
  // ShadeParams::stereoLayer): their sums as above and their premultiplied radiance. The rest is
  // the back layer (stereo.h).
  float frontSums[3];
  float frontRgb[3];
  float frontLimit;  // -1 before the sample that opens the front layer
};

// A sample of at least this weight (its share of the pixel) opens a pixel's front layer: fainter
// ones before it (a wisp in front of a crown) join the front layer without setting its depth.
constexpr float kLayerOpenWeight = 0.02f;

// kWithDepth: adds a sample of weight w = T alpha at inverse depth inv (1 / t), whose radiance add
// was added to r.rgb, to the depth sums and, while the ray is in its front layer, to the front
// layer's; window: the front layer's depth in inverse depth. Samples come in ray order (inv never
// grows), so once one falls behind the front layer every later one does.
CANOPY_HD CANOPY_FORCEINLINE void addDepthSample(ConeResult& r, float w, float inv, const float add[3], float window) {
  r.depthSums[0] += w;
  r.depthSums[1] += w * inv;
  r.depthSums[2] += w * inv * inv;
  if (r.frontLimit < 0.0f && w >= kLayerOpenWeight) r.frontLimit = inv - window;
  if (inv < r.frontLimit) return;
  r.frontSums[0] += w;
  r.frontSums[1] += w * inv;
  r.frontSums[2] += w * inv * inv;
  for (int c = 0; c < 3; ++c) r.frontRgb[c] += add[c];
}

// Transmittance from p towards the sun (shadow cone, footprint starts at `footprint0`).
CANOPY_HD inline float shadowTransmittance(const SceneView& s, V3 p, float footprint0) {
  const V3 d = s.shade.toSun;
  CANOPY_PLAY_COUNT(s, shadowCones, 1);
  HitSlots slots;
  InstanceWalk w;
  walkBegin(s, w, slots, p, d, 0.0f, 3.0e38f);
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

// Host only (--count-work): a shading segment of `inst` at a cone footprint `footprint` (world: one
// pixel's width there) counted by the width of the voxel its level has, in pixels (WorkCounters::
// voxelPixels). The level is the rule's (segmentLevel: the coarsest whose voxel is no wider than
// the footprint, never finer than the finest), so the ratio is at most 1 wherever the finest voxel
// is narrower than the footprint, and above 1 only where the model's finest voxel is wider than a
// pixel (a close view of a coarse lattice). Not counted on the GPU.
CANOPY_HD inline void countVoxelFootprint(const SceneView& s, const InstanceView& inst, float footprint) {
#if !defined(__CUDA_ARCH__)
  if (!s.work || !(footprint > 0.0f)) return;
  const uint32_t depth = s.models[inst.model].depth;
  const uint32_t level = segmentLevel(s, inst, depth, footprint);
  const float ratio = float(1u << (depth - level)) * inst.cellWorld / footprint;
  const int bin = ratio <= 1.0f ? 0 : (ratio <= 1.5f ? 1 : (ratio <= 4.0f ? 2 : 3));
  __atomic_fetch_add(&s.work->voxelPixels[bin], uint64_t(1), __ATOMIC_RELAXED);
  uint32_t bits;
  memcpy(&bits, &ratio, sizeof bits);  // a positive float's bits order as its value
  uint64_t cur = __atomic_load_n(&s.work->maxVoxelPixelsBits, __ATOMIC_RELAXED);
  while (bits > cur && !__atomic_compare_exchange_n(&s.work->maxVoxelPixelsBits, &cur, uint64_t(bits), true, __ATOMIC_RELAXED,
                                                    __ATOMIC_RELAXED)) {
  }
#else
  (void)s, (void)inst, (void)footprint;
#endif
}

// The sums of one step of the primary cone over its hits: extinction, extinction x albedo (which
// the step's sun transmittance will scale) and that times its indirect light (which depends on the
// segment alone: its light is sampled at its own point). Each segment with matter is shaded as it is
// found; no per-hit segment array is kept for a second pass (it was 16 x 64 bytes of local memory
// written at every step).
struct StepSums {
  float next;       // the step's end: the nearest bound of its hits and of the walk's cell
  float k, kAlbedo[3], kIndirect[3];
  bool active;      // a hit has begun (is not pending)
  float minCell;    // the finest lattice cell of the active hits (world; shadow cones only)
};

// The first of the step's two passes over the hits. It is cheap (pending hits and held empty
// segments only bound the step) and returns which hits must be evaluated; the second
// (evaluateHits) evaluates them, in the same ascending order, so the sums are the same bit for
// bit. On the GPU this is what lets a warp run instanceSegment() once for all its lanes: in one loop
// doing both, a lane that evaluates its first hit and a lane that evaluates its third ran the
// evaluation at different iterations, one after the other (docs/performance.md, 'Warp-uniform
// evaluation').
template <bool kWithCones>
CANOPY_HD CANOPY_FORCEINLINE uint32_t boundStep(const SceneView& s, const InstanceWalk& w, float t, StepSums& q) {
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
    q.next = (pending || held) && bound < q.next ? bound : q.next;
    q.active = q.active || !pending;
    evaluate |= uint32_t(!pending && !held) << h;
    CANOPY_PLAY_COUNT(s, heldSegments, held ? 1 : 0);
    if (kWithCones && !pending) {  // the shadow interval's length (shadeStep)
      const float cell = s.instances[w.hits[h].instance].cellWorld;
      q.minCell = cell < q.minCell ? cell : q.minCell;
    }
  }
  return evaluate;
}

// The second pass: evaluates the hits of `evaluate` at t (instanceSegment) into the step's sums.
template <bool kWithLight, uint32_t kPaths>
CANOPY_HD CANOPY_FORCEINLINE void evaluateHits(const SceneView& s, InstanceWalk& w, V3 o, V3 d, float t, float pixelAngle,
                                               uint32_t evaluate, float grow, StepSums& q) {
  const float footprint = t * pixelAngle;
  while (evaluate != 0) {
    const uint32_t h = lowestSetBit(evaluate);
    evaluate &= evaluate - 1u;
    Hit& hit = w.hits[h];
    const InstanceView& inst = s.instances[hit.instance];
    const Segment g = instanceSegment<kPaths>(s, inst, o, d, t, hit.tout, footprint, true, w.caches[h],
                                      s.shade.holdEmpty ? &hit.hold : nullptr, grow);
    if (hit.hold.until > t) {  // a new hold: its level condition becomes a bound on t
      const float limit = levelHoldsUntil(s, inst, s.models[inst.model].depth, pixelAngle, hit.hold.level);
      hit.hold.until = limit < hit.hold.until ? limit : hit.hold.until;
    }
    q.next = g.tEnd < q.next ? g.tEnd : q.next;
    if (g.k <= 0.0f) continue;
    countVoxelFootprint(s, inst, footprint);
    q.k += g.k;
    float ind[3];
    segmentIndirect<kWithLight, kPaths>(s, inst, g, o, d, ind);
    for (int c = 0; c < 3; ++c) {
      const float ka = g.k * g.albedo[c];
      q.kAlbedo[c] += ka;
      q.kIndirect[c] += ka * ind[c];
    }
  }
}

// How much a primary cone's brick steps grow at transmittance T (ShadeParams::stepGrowthT): 1 while
// T >= stepGrowthT, then stepGrowthT / T, at most stepGrowthMax. A sample's share of the pixel is
// at most T, so the error of a longer step there is weighted by T: the growth keeps T x step
// about constant (the sampling rate falls as what is left to see does).
CANOPY_HD CANOPY_FORCEINLINE float stepGrowth(const ShadeParams& shade, float T) {
  if (!(T < shade.stepGrowthT)) return 1.0f;
  const float g = shade.stepGrowthT / T;
  return g < shade.stepGrowthMax ? g : shade.stepGrowthMax;
}

// The sun's transmittance at the primary cone's samples, and the shadow cone whose value later
// samples reuse (kShadowsCone).
struct SunAtSample {
  float sunT = 1.0f;
  float shadowT = -3.0e38f;  // the last shadow cone's origin (ray parameter)
  float spacing = 0.0f;      // samples closer than this to it reuse its value
  float refT = 2.0f;         // the primary cone's transmittance there
};

// Shades the step [t, next) of extinction q.k: its radiance into r (and the inverse-depth moments,
// kWithDepth, and the layers: window, addDepthSample), weighted by the transmittance T before it;
// returns the step's alpha.
template <bool kWithCones, bool kWithDepth>
CANOPY_HD CANOPY_FORCEINLINE float shadeStep(const SceneView& s, V3 o, V3 d, float t, float pixelAngle, const StepSums& q, float T,
                                             SunAtSample& sun, ConeResult& r, float window) {
  const float dt = q.next - t;
  const float alpha = 1.0f - expf(-q.k * dt);
  if (!(alpha > 0.0f && T * alpha > kMinContribution)) return alpha;
  const float tm = t + 0.5f * dt;
  const V3 p = o + d * tm;
  CANOPY_PLAY_COUNT(s, shadedSamples, 1);
  if (s.shade.shadows == kShadowsMap) {
    sun.sunT = shadowMapLookup(s.shadowMap, p);
    CANOPY_PLAY_COUNT(s, shadowMapLookups, 1);
  } else if (kWithCones && s.shade.shadows == kShadowsCone && (!(tm - sun.shadowT < sun.spacing) || T < kShadowReuseT * sun.refT)) {
    // One shadow cone per shadow interval: samples closer than about a voxel (1.5 cells of the
    // nearest active instance, or two footprints) to the last shadow origin reuse its value,
    // unless the primary ray has since crossed matter of optical depth 0.051 (its T fell by 5 %):
    // a dense interval's deeper samples are darker than its first. (Reusing over the whole interval
    // made the direct sun 25-31 % too bright on a 40^3 oak against the path tracer,
    // docs/validation.md.)
    const float footprint = t * pixelAngle;
    sun.sunT = shadowTransmittance(s, p, footprint);
    sun.shadowT = tm;
    sun.refT = T;
    sun.spacing = 2.0f * footprint > 1.5f * q.minCell ? 2.0f * footprint : 1.5f * q.minCell;
  }
  const float scale = T * alpha / q.k;
  // Two branches on purpose: with one loop through add[3] for both, nvcc kept add[] in local memory
  // in the mono shadow-cone kernel and summed with a multiply and an add instead of one fma, so its
  // CUDA frames moved by rounding (the CPU's did not).
  if (kWithDepth) {
    float add[3];
    for (int c = 0; c < 3; ++c) {
      add[c] = scale * (q.kAlbedo[c] * s.shade.direct[c] * sun.sunT + q.kIndirect[c]);
      r.rgb[c] += add[c];
    }
    addDepthSample(r, T * alpha, 1.0f / tm, add, window);
  } else {
    for (int c = 0; c < 3; ++c) r.rgb[c] += scale * (q.kAlbedo[c] * s.shade.direct[c] * sun.sunT + q.kIndirect[c]);
  }
  return alpha;
}

// The ground at ray parameter tGround behind what is left of the transmittance T: its radiance
// into r (and its inverse depth, kWithDepth).
template <bool kWithCones, bool kWithDepth>
CANOPY_HD CANOPY_FORCEINLINE void addGround(const SceneView& s, V3 o, V3 d, float tGround, float pixelAngle, float T, ConeResult& r,
                                            float window) {
  float g[3];
  groundRadiance<kWithCones>(s, o + d * tGround, tGround * pixelAngle, g);
  for (int c = 0; c < 3; ++c) r.rgb[c] += T * g[c];
  if (kWithDepth) {
    const float add[3] = {T * g[0], T * g[1], T * g[2]};
    addDepthSample(r, T, 1.0f / tGround, add, window);
  }
}

// Where a primary cone of `pixelAngle` leaves the instances for the far field (3e38: never):
// shade.farStart where it is a distance (> 0), else (auto) where the cone's footprint reaches the
// far field's voxel, the coarsest level's voxel of the coarsest instance: beyond it every instance
// would be sampled at its coarsest level, with voxels narrower than the footprint.
CANOPY_HD inline float farFieldStart(const SceneView& s, float pixelAngle) {
  if (!s.far.values || s.shade.farStart < 0.0f) return 3.0e38f;
  if (s.shade.farStart > 0.0f) return s.shade.farStart;
  return pixelAngle > 0.0f ? s.far.voxel / pixelAngle : 3.0e38f;
}

// The far field's part of a primary cone from t0 to t1: false where the ray misses the grid's box
// (its voxel centres: trilinear reads 0 outside it) there, else true with [t, tEnd) the part inside.
CANOPY_HD inline bool farFieldSpan(const FarFieldView& f, V3 o, V3 d, float t0, float t1, float& t, float& tEnd) {
  const V3 lo = v3(f.lo[0], f.lo[1], f.lo[2]);
  const V3 hi = lo + v3(float(f.dim[0] - 1), float(f.dim[1] - 1), float(f.dim[2] - 1)) * f.voxel;
  float tIn, tOut;
  rayBox(o, d, lo, hi, tIn, tOut);
  t = t0 > tIn ? t0 : tIn;
  tEnd = t1 < tOut ? t1 : tOut;
  return t < tEnd;
}

// One step of a primary cone through the far field from t (before tEnd): stepFactor far-field
// voxels, one trilinear sample of the prefiltered extinction and albedo at its middle, as the step
// sums shadeStep takes (the indirect term the density-only one, ambient times the scene lattice's
// ambient factor, as a model without LB light has; minCell the far field's voxel, so a shadow
// cone's value serves samples within 1.5 of it).
CANOPY_HD inline StepSums farFieldStep(const SceneView& s, V3 o, V3 d, float t, float tEnd) {
  const FarFieldView& f = s.far;
  const float ds = s.shade.stepFactor * f.voxel;
  StepSums q = {t + ds < tEnd ? t + ds : tEnd, 0.0f, {0.0f, 0.0f, 0.0f}, {0.0f, 0.0f, 0.0f}, true, f.voxel};
  CANOPY_PLAY_COUNT(s, farSteps, 1);
  const V3 p = o + d * (0.5f * (t + q.next));
  float v[kFarFieldChannels];
  gridTrilinear<kFarFieldChannels>(f.values, f.lo, f.voxel, f.dim, p, v);
  if (v[0] > 0.0f) {
    float ind[3];
    ambientOnly(s, sceneLightFactors(s.light, p), ind);
    q.k = v[0];
    for (int c = 0; c < 3; ++c) {
      q.kAlbedo[c] = v[1 + c];
      q.kIndirect[c] = v[1 + c] * ind[c];
    }
  }
  return q;
}

// One primary cone: origin o, unit direction d, footprint(t) = footprint0 + t * pixelAngle.
// kWithCones: compiled with the shadow-cone path (kShadowsCone); without it that mode is treated
// as kShadowsOff, so the CUDA kernel of the other modes carries neither the shadow cone's instance
// walk (its hit list and descent caches in local memory) nor its registers. Same code otherwise.
// kWithDepth: also sums the inverse-depth moments of the shaded samples (ConeResult::depthSums) and
// of its front layer, the samples within `window` (inverse depth) of the first one of weight
// kLayerOpenWeight or more (addDepthSample).
// A ray that meets the ground (groundHit) before tMax is marched up to it (the parts of instances
// below the plane are cut) and ends there: what is left of its transmittance shows the ground
// (groundRadiance), and the result is opaque. With a far field the instances are marched up to
// farFieldStart and the far field from there (farFieldSpan, farFieldStep), in the same loop.
// The march starts at tStart with transmittance T0 (a stereo hole behind a reprojected layer: behind
// it, with what that layer lets through, so that the march stops where the whole ray's would).
// Each step: retire the hits that ended, bound the step and evaluate the hits that need it
// (boundStep, evaluateHits), shade it (shadeStep), move the walk on.
// kPaths: the optional paths compiled in (scene_view.h scenePaths); without kPathFar the far field
// is not marched (s.far is not read).
template <bool kWithCones, bool kWithLight = true, bool kWithDepth = false, uint32_t kPaths = kAllPaths>
CANOPY_HD inline ConeResult traceCone(const SceneView& s, V3 o, V3 d, float pixelAngle, float tMax, float window = 0.0f,
                                      float tStart = 0.0f, float T0 = 1.0f) {
  ConeResult r;
  r.rgb[0] = r.rgb[1] = r.rgb[2] = 0.0f;
  r.transmittance = 1.0f;
  r.depthSums[0] = r.depthSums[1] = r.depthSums[2] = 0.0f;
  r.frontSums[0] = r.frontSums[1] = r.frontSums[2] = 0.0f;
  r.frontRgb[0] = r.frontRgb[1] = r.frontRgb[2] = 0.0f;
  r.frontLimit = -1.0f;
  CANOPY_PLAY_COUNT(s, cones, 1);
  const float tGround = groundHit(s.shade, o, d);
  const bool ground = tGround < tMax;
  if (ground) tMax = tGround;
  constexpr bool kFar = (kPaths & kPathFar) != 0;
  const float tFar = kFar ? farFieldStart(s, pixelAngle) : 3.0e38f;
  const float tNear = tFar < tMax ? tFar : tMax;  // the instances' part of the ray
  HitSlots slots;
  InstanceWalk w;
  walkBegin(s, w, slots, o, d, tStart, tNear);
  float t = tStart;
  float T = T0;
  SunAtSample sun;
  // The far field's part, once the instances' has ended (one loop and one shadeStep for both, so
  // that the far field adds little to the kernel): farEnd > 0 while it is marched.
  float farEnd = -1.0f;
  while (true) {
    StepSums q;
    if (!kFar || farEnd < 0.0f) {
      walkRetire(w, t);
      bool ended = w.live == 0 && w.done;
      if (!ended) {
        q = {w.done ? tNear : w.tCellExit, 0.0f, {0.0f, 0.0f, 0.0f}, {0.0f, 0.0f, 0.0f}, false, 3.0e38f};
        const uint32_t evaluate = boundStep<kWithCones>(s, w, t, q);
        evaluateHits<kWithLight, kPaths>(s, w, o, d, t, pixelAngle, evaluate, stepGrowth(s.shade, T), q);
        // No hit in this cell: an empty step to its exit (q.next), where the walk moves on below
        // (one call site of walkAdvance in this loop, not two: these kernels wait on their code)
        if (!q.active && w.live == 0) ended = w.done;
      }
      if (ended) {  // no instance left before tNear: the far field from tNear on, if any
        if (!kFar || !(tNear < tMax) || !farFieldSpan(s.far, o, d, tNear > t ? tNear : t, tMax, t, farEnd)) break;
        continue;
      }
      if (q.next > tNear) q.next = tNear;
      CANOPY_PLAY_COUNT(s, primarySteps, 1);
      if (q.k == 0.0f) CANOPY_PLAY_COUNT(s, emptySteps, 1);
    } else {
      if (!(t < farEnd)) break;
      q = farFieldStep(s, o, d, t, farEnd);
      if (!(q.next > t)) break;  // a step below float resolution at t (an absurd scale): stop rather than loop
    }
    const float alpha = shadeStep<kWithCones, kWithDepth>(s, o, d, t, pixelAngle, q, T, sun, r, window);
    T *= 1.0f - alpha;
    t = q.next;
    if (T < s.shade.stopT) break;
    if (!kFar || farEnd < 0.0f) {
      if (t >= tNear) {
        if (!kFar || !(tNear < tMax) || !farFieldSpan(s.far, o, d, t, tMax, t, farEnd)) break;
        continue;
      }
      while (!w.done && t >= w.tCellExit) walkAdvance(s, w, o, d, t);
    }
  }
  if (ground) {
    addGround<kWithCones, kWithDepth>(s, o, d, tGround, pixelAngle, T, r, window);
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

// What stereo reprojection keeps of a traced pixel besides its RGBA (stereo.h), kStereoPixelFloats
// floats: the front layer's disparity (mean, spread), the back layer's (mean, spread), the front
// layer's premultiplied RGBA (alpha = the front samples' share of the pixel), and the disparity of
// the front layer's far side, where the back layer begins (ConeResult::frontLimit; 0: the front
// layer never opened).
constexpr int kStereoPixelFloats = 9;
CANOPY_HD inline void pixelLayers(const ConeResult& r, float cosAxis, float disparityScale, float out[kStereoPixelFloats]) {
  const float back[3] = {r.depthSums[0] - r.frontSums[0], r.depthSums[1] - r.frontSums[1], r.depthSums[2] - r.frontSums[2]};
  pixelDisparity(r.frontSums, cosAxis, disparityScale, out);
  pixelDisparity(back, cosAxis, disparityScale, out + 2);
  for (int c = 0; c < 3; ++c) out[4 + c] = r.frontRgb[c];
  out[7] = r.frontSums[0];
  out[8] = r.frontLimit > 0.0f ? disparityScale * r.frontLimit / cosAxis : 0.0f;
}

// Renders pixel i of the frame into rgba (premultiplied RGB, alpha = 1 - T). kWithCones must be
// true when s.shade.shadows == kShadowsCone, kWithLight when s.litModels > 0 (renderPixel() picks
// them; the CUDA backend launches the kernel of the mode and scene). `stereo`:
//   - kWithDepth (stereo's traced eye): written, what reprojection keeps of the pixel,
//     stereo[kStereoPixelFloats i ...] (pixelLayers: its layers' disparities in pixels, for an eye
//     separation of disparityScale / focal, and its front layer's RGBA);
//   - kBehind (stereo's holes, stereoResolveHole): read, stereo[i] > 0: the ray is traced from
//     disparity stereo[i] on (depth disparityScale / stereo[i]) and composited under the RGBA in
//     rgba (a reprojected layer in front of it); else traced in full.
template <bool kWithCones, bool kWithLight, bool kWithDepth = false, bool kBehind = false, uint32_t kPaths = kAllPaths>
CANOPY_HD inline void renderPixelT(const SceneView& s, const CameraView& c, int64_t i, float* rgba, float* stereo = nullptr,
                                   float disparityScale = 0.0f) {
  const int x = int(i % c.width), y = int(i / c.width);
  float fpPerT;
  const V3 d = cameraRay(c, x, y, fpPerT);
  const float cosAxis = dot(d, c.forward);
  // the front layer's depth in inverse depth: stereoLayer pixels of disparity (pixelDisparity)
  const float window = kWithDepth && disparityScale > 0.0f ? s.shade.stereoLayer * cosAxis / disparityScale : 0.0f;
  const bool behind = kBehind && stereo[i] > 0.0f;
  const float tStart = behind ? disparityScale / (stereo[i] * cosAxis) : 0.0f;
  // a hole's ray under the ground before its start sees only the front written in rgba
  if (behind && groundHit(s.shade, c.position, d) <= tStart) return;
  // behind a front: marched with what the front lets through, so the radiance is already weighted
  // and the transmittance is the whole ray's
  const float T0 = behind ? 1.0f - rgba[4 * i + 3] : 1.0f;
  const ConeResult r = traceCone<kWithCones, kWithLight, kWithDepth, kPaths>(s, c.position, d, fpPerT, 3.0e37f, window, tStart, T0);
  if (behind) {
    for (int ch = 0; ch < 3; ++ch) rgba[4 * i + ch] += r.rgb[ch];
    rgba[4 * i + 3] = 1.0f - r.transmittance;
  } else {
    rgba[4 * i + 0] = r.rgb[0];
    rgba[4 * i + 1] = r.rgb[1];
    rgba[4 * i + 2] = r.rgb[2];
    rgba[4 * i + 3] = 1.0f - r.transmittance;
  }
  if (kWithDepth) pixelLayers(r, cosAxis, disparityScale, stereo + kStereoPixelFloats * i);
}

// The map's (or no-shadow) renderPixelT compiled with the optional paths `paths` (scenePaths; for
// stereo's kWithDepth and kBehind, stereoPaths) and no others: kPaths runs from 0 up to the one
// asked for, over the sets compiled for the mode.
template <bool kWithLight, bool kWithDepth, bool kBehind, uint32_t kPaths = 0>
CANOPY_HD inline void renderPixelOfPaths(uint32_t paths, const SceneView& s, const CameraView& c, int64_t i, float* rgba, float* stereo,
                                         float disparityScale) {
  if constexpr (kPaths < kAllPaths) {
    constexpr uint32_t kNext = nextPathSet(kPaths, kWithDepth || kBehind);
    if (paths != kPaths) return renderPixelOfPaths<kWithLight, kWithDepth, kBehind, kNext>(paths, s, c, i, rgba, stereo, disparityScale);
  }
  renderPixelT<false, kWithLight, kWithDepth, kBehind, kPaths>(s, c, i, rgba, stereo, disparityScale);
}

// renderPixelT of the scene's shadow path and light (s.shade.shadows, s.litModels) in stereo mode
// kWithDepth / kBehind; the map's with the frame's paths only (scenePaths, stereoPaths), as the
// CUDA backend launches it. Shadow cones take every path.
template <bool kWithDepth, bool kBehind>
CANOPY_HD inline void renderPixelOfScene(const SceneView& s, const CameraView& c, int64_t i, float* rgba, float* stereo,
                                         float disparityScale) {
  const bool cones = s.shade.shadows == kShadowsCone, light = s.litModels > 0;
  const uint32_t paths = kWithDepth || kBehind ? stereoPaths(scenePaths(s)) : scenePaths(s);
  if (cones)
    light ? renderPixelT<true, true, kWithDepth, kBehind>(s, c, i, rgba, stereo, disparityScale)
          : renderPixelT<true, false, kWithDepth, kBehind>(s, c, i, rgba, stereo, disparityScale);
  else
    light ? renderPixelOfPaths<true, kWithDepth, kBehind>(paths, s, c, i, rgba, stereo, disparityScale)
          : renderPixelOfPaths<false, kWithDepth, kBehind>(paths, s, c, i, rgba, stereo, disparityScale);
}

// renderPixelT of the mode and scene: with depth (stereo's traced eye) when `depth` is set, as
// stereo's holes when `behind` is (renderPixelT's `stereo`).
CANOPY_HD inline void renderPixel(const SceneView& s, const CameraView& c, int64_t i, float* rgba, float* depth = nullptr,
                                  float disparityScale = 0.0f, float* behind = nullptr) {
  if (depth)
    renderPixelOfScene<true, false>(s, c, i, rgba, depth, disparityScale);
  else if (behind)
    renderPixelOfScene<false, true>(s, c, i, rgba, behind, disparityScale);
  else
    renderPixelOfScene<false, false>(s, c, i, rgba, nullptr, 0.0f);
}

}  // namespace canopy::play
