// cone_light.h: the LB light of a sample (light items, Haar items, the coarse scene lattice's factors).
// Part of runtime/cone.h.
#pragma once
#include "runtime/scene_view.h"

namespace canopy::play {

// ------------------------------------------------------------------------------------------------
// Lighting
// ------------------------------------------------------------------------------------------------

// The coarse scene factors at world point p (trilinear, clamped to the lattice; 1 without one):
// one trilinear lookup of the node pairs (a pair is one 8-byte load per corner). Branch-free: the
// eight corners' offsets are fixed before any is read (a corner past the lattice's last node reads
// that node, with weight 0 unless the lattice is one node thick there), so the eight loads issue
// together; the sum is taken in corner order as w_c x value_c (a zero weight adds +0, as the
// skipped term did: the same bits as the loop that skipped it, measured 18-21 % of the real
// forest's frame on an H200 before the change). Node indices in 32 bits (addSceneLight refuses a
// lattice of 2^32 nodes or more): with the shadow map's, 0.98-0.99x the real forest's frame time of
// 64-bit indices on one H100.
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
  const uint32_t sy = uint32_t(L.dim[0]), sz = uint32_t(L.dim[0]) * uint32_t(L.dim[1]);
  const uint32_t ox = L.dim[0] > 1 ? 1u : 0u, oy = L.dim[1] > 1 ? sy : 0u, oz = L.dim[2] > 1 ? sz : 0u;
  const SceneLightPair* b = L.values + (uint32_t(i0[0]) + sy * uint32_t(i0[1]) + sz * uint32_t(i0[2]));
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

// lbIndirect()'s sum (the same terms in the same order) over bases that `sample(base, rgb)` gives at
// the sample point: the sun bases of w, each times its weight, scaled by the sun radiance and the
// scene's sun factor, then B_0's term, ambient B_0 / 18 * ambientFactor. A zero weight's base is not
// sampled (it would add +0: a base's value is finite). On the device the four bases run in a rolled
// loop, one copy of the sampler: unrolled, the light items' four copies were 6.8 KB of the forest's
// 56.8 KB lit map kernel, all in the march's loop; rolled, the real forest's frames took 0.86-0.90x the
// time on one H100 (docs/performance.md, "Kernel code size").
template <class SampleBase>
CANOPY_HD CANOPY_FORCEINLINE void lbBaseSum(const sun::Weights& w, const float sun[3], float ambient, float sunFactor,
                                            float ambientFactor, const SampleBase& sample, float out[3]) {
  float acc[3] = {0.0f, 0.0f, 0.0f};
#if defined(__CUDA_ARCH__)
#pragma unroll 1
#endif
  for (int v = 0; v < 4; ++v) {
    if (v == 3) {  // the three sun bases are summed: scale them by the sun radiance and the scene's sun factor before B_0 joins
      for (int c = 0; c < 3; ++c) acc[c] = acc[c] * sun[c] * sunFactor;
    }
    const float weight = v == 0 ? w.weight[0] : v == 1 ? w.weight[1] : v == 2 ? w.weight[2] : ambient * kAmbientB0Scale;
    if (!(weight != 0.0f)) continue;
    const uint32_t base = v == 0 ? uint32_t(w.base[0]) : v == 1 ? uint32_t(w.base[1]) : v == 2 ? uint32_t(w.base[2]) : 0u;
    float b[3];
    sample(base, b);
    const float f = v == 3 ? ambientFactor : 1.0f;  // B_0's term: ambient B_0 / 18 * ambientFactor (x 1 is exact)
    for (int c = 0; c < 3; ++c) acc[c] += weight * b[c] * f;
  }
  for (int c = 0; c < 3; ++c) out[c] = acc[c];
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
// footprint's kept coefficients, haar_brick.h) the grove takes 17.3 ms, the light items
// (--light fast, then float16) 16.4 ms (2026-12-01).
// The sun radiance comes by value: a pointer into the kernel's parameters, passed to this
// out-of-line function, made the whole lit kernel 10 % slower on the grove (measured: 18.0 against
// 16.3 ms per 1080p frame on an H200), although --light fast never calls it.
CANOPY_HD CANOPY_PLAY_NOINLINE void sampleHaarLbLight(const unsigned char* item, uint32_t fp16, const haar::BrickLookup& at,
                                                      const sun::Weights& w, haar::Rgb sun, float ambient,
                                                      float sunFactor, float ambientFactor, float out[3]) {
  if (!item) {
    out[0] = out[1] = out[2] = 0.0f;
    return;
  }
  const float sunRgb[3] = {sun.r, sun.g, sun.b};
  lbBaseSum(w, sunRgb, ambient, sunFactor, ambientFactor, [&](uint32_t base, float rgb[3]) {
    const haar::Rgb c = canopyHaarSampleAt(item, fp16, base, at);
    rgb[0] = c.r, rgb[1] = c.g, rgb[2] = c.b;
  }, out);
}

// The LB indirect light from a light item at node-local l in [0,1]^3: the (up to) three sun bases
// of the instance's lookup and B_0, each trilinear (canopySampleLight's interpolation, the corners
// found once), summed as lbIndirect() sums them (lbBaseSum).
CANOPY_HD inline void sampleLbLight(const uint32_t* item, const sun::Weights& w, float lx, float ly, float lz,
                                    const float sun[3], float ambient, SceneLightPair scene, float out[3]) {
  const CanopyLightCorners k = canopyLightCorners(lx, ly, lz);
  lbBaseSum(w, sun, ambient, scene.sun, scene.ambient, [&](uint32_t base, float rgb[3]) { canopySampleLightAt(item, base, k, rgb); }, out);
}

}  // namespace canopy::play
