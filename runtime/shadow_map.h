// shadow_map.h: the sun transmittance map (kShadowsMap): the scene's extinction grid and the
// frame's map, built by the backends and read per sample. Part of runtime/cone.h.
#pragma once
#include "runtime/cone_walk.h"

namespace canopy::play {

// ------------------------------------------------------------------------------------------------
// The sun transmittance map (kShadowsMap)
// ------------------------------------------------------------------------------------------------
// Two grids. (1) The scene's EXTINCTION GRID (world axes, built once per scene by the backend):
// at each voxel centre the sum, over the instances whose lattice box holds the point (found
// through the instance grid), of sigma x the node mean density / the instance's cell, the node
// being the one of edge <= 2 voxels on the descent (node tiles are always resident, so the grid
// needs no page, is the same for every cache state and is ready at the first frame). (2) The
// frame's TRANSMITTANCE MAP (light space, built again only when the sun's direction has changed,
// Backend::buildShadowMap): each column is a ray from the sun,
// marched front to back through the extinction grid (trilinear, steps of at most one extinction
// voxel); T at a voxel centre = exp(-optical depth from the sun). A sample reads T trilinearly.
// The cost is one march per map column per build (independent of the image and of the number of
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
// most `maxNode` (world). kAlbedo (optional): each instance's extinction times its node's albedo is
// added to it (the far field's second to fourth channels).
CANOPY_HD inline float sceneMeanExtinctionAt(const SceneView& s, V3 x, float maxNode, float* kAlbedo = nullptr) {
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
    const CanopySample c = canopyUnpack(n.node.density, n.node.material);
    const float ki = s.shade.sigma * c.density / (inst.cellWorld / m.extinctionScale);  // per light cell
    k += ki;
    if (kAlbedo)
      for (int ch = 0; ch < 3; ++ch) kAlbedo[ch] += ki * c.albedo[ch];
  }
  return k;
}

// The world centre of voxel i (x fastest) of a grid whose voxel (0, 0, 0) is centred at lo.
CANOPY_HD CANOPY_FORCEINLINE V3 gridVoxelCentre(const float lo[3], float voxel, const int32_t dim[3], int64_t i) {
  const int x = int(i % dim[0]);
  const int y = int((i / dim[0]) % dim[1]);
  const int z = int(i / (int64_t(dim[0]) * dim[1]));
  return v3(lo[0] + float(x) * voxel, lo[1] + float(y) * voxel, lo[2] + float(z) * voxel);
}

// The extinction grid's voxel i (x fastest): the mean of 2x2x2 samples at +-voxel/4 about its
// centre (a box filter, so that a face of matter that falls on a voxel centre keeps its mass once
// the grid is read trilinearly).
CANOPY_HD inline void buildExtinctionVoxel(const SceneView& s, const ExtinctionGridView& g, int64_t i) {
  const V3 c = gridVoxelCentre(g.lo, g.voxel, g.dim, i);
  const float q = 0.25f * g.voxel;
  float k = 0.0f;
  for (int j = 0; j < 8; ++j)
    k += sceneMeanExtinctionAt(s, c + v3((j & 1) ? q : -q, (j & 2) ? q : -q, (j & 4) ? q : -q), 2.0f * g.voxel);
  g.k[i] = 0.125f * k;
}

// Trilinear values at world point p of a grid of N channels per voxel (x fastest; voxel (0, 0, 0)'s
// centre at lo): out[] = 0 outside the grid, whose border voxels are empty, and false returned.
template <int N>
CANOPY_HD inline bool gridTrilinear(const float* values, const float lo[3], float voxel, const int32_t dim[3], V3 p, float out[N]) {
  const float inv = 1.0f / voxel;
  int i0[3];
  float f[3];
  for (int a = 0; a < 3; ++a) {
    const float x = (comp(p, a) - lo[a]) * inv;
    if (!(x >= 0.0f) || !(x < float(dim[a] - 1))) {
      for (int c = 0; c < N; ++c) out[c] = 0.0f;
      return false;
    }
    const float fl = floorf(x);
    i0[a] = int(fl);
    f[a] = x - fl;
  }
  const int64_t sx = N, sy = int64_t(N) * dim[0], sz = sy * dim[1];
  const float* b = values + sx * i0[0] + sy * i0[1] + sz * i0[2];
  for (int c = 0; c < N; ++c, ++b) {
    const float c00 = b[0] + (b[sx] - b[0]) * f[0];
    const float c10 = b[sy] + (b[sy + sx] - b[sy]) * f[0];
    const float c01 = b[sz] + (b[sz + sx] - b[sz]) * f[0];
    const float c11 = b[sz + sy] + (b[sz + sy + sx] - b[sz + sy]) * f[0];
    const float c0 = c00 + (c10 - c00) * f[1];
    const float c1 = c01 + (c11 - c01) * f[1];
    out[c] = c0 + (c1 - c0) * f[2];
  }
  return true;
}

// Trilinear extinction at world point p (0 outside the grid, whose border voxels are empty).
CANOPY_HD inline float extinctionAt(const ExtinctionGridView& g, V3 p) {
  float k;
  gridTrilinear<1>(g.k, g.lo, g.voxel, g.dim, p, &k);
  return k;
}

// The far field's voxel i (x fastest): at its centre, the node-mean extinction and extinction x
// albedo of every instance there, nodes of edge at most a voxel (the size of the instance's
// coarsest voxels: what its own coarsest level holds there). One sample, not the extinction grid's
// 2x2x2 box: on the far-field test stand the box's extra blur took the frame from 15 % to 23 % RMS
// of the per-instance one (silhouettes a voxel taller); a sample may fall in a node that straddles
// the voxel, so mass is kept only on average.
CANOPY_HD inline void buildFarFieldVoxel(const SceneView& s, const FarFieldView& g, int64_t i) {
  const V3 c = gridVoxelCentre(g.lo, g.voxel, g.dim, i);
  float ka[3] = {0.0f, 0.0f, 0.0f};
  const float k = sceneMeanExtinctionAt(s, c, g.voxel, ka);
  float* v = g.values + kFarFieldChannels * i;
  v[0] = k;
  for (int ch = 0; ch < 3; ++ch) v[1 + ch] = ka[ch];
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
// does not shadow it. Voxel indices in 32 bits: the map has at most 2^28 voxels (--shadow-map-voxels).
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
  const uint32_t sx = 1, sy = uint32_t(m.dim[0]), sz = uint32_t(m.dim[0]) * uint32_t(m.dim[1]);
  const float* b = m.T + (uint32_t(i0[0]) + sy * uint32_t(i0[1]) + sz * uint32_t(i0[2]));
  const uint32_t dx = m.dim[0] > 1 ? sx : 0u, dy = m.dim[1] > 1 ? sy : 0u, dz = m.dim[2] > 1 ? sz : 0u;
  const float c00 = b[0] + (b[dx] - b[0]) * f[0];
  const float c10 = b[dy] + (b[dy + dx] - b[dy]) * f[0];
  const float c01 = b[dz] + (b[dz + dx] - b[dz]) * f[0];
  const float c11 = b[dz + dy] + (b[dz + dy + dx] - b[dz + dy]) * f[0];
  const float c0 = c00 + (c10 - c00) * f[1];
  const float c1 = c01 + (c11 - c01) * f[1];
  return c0 + (c1 - c0) * f[2];
}

}  // namespace canopy::play
