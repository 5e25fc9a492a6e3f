// voxelize.cpp: the rasteriser (see voxelize.h for what it computes).
//
// Pipeline: bin triangles into tiles of 8^3 lattice cells (only tiles a triangle's bounding box
// meets), then process tiles in parallel. Within a tile each lattice cell owns two bitmasks of its
// supersample^3 fine sub-cells (touched by counted geometry; touched by wood) and a colour sum;
// with --detail each touched cell also gets a colour sum and touch count per detail cell (its k^3
// sub-blocks of (S/k)^3 sub-cells). One function (cellValues) turns counts and sums into a cell's
// values for both lattices. Triangles are rasterised in file order, so sums and results are
// identical at any thread count.
#include "voxelize.h"

#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <regex>
#include <unordered_map>

#include "canopy/cli.h"
#include "canopy/errors.h"
#include "exact_overlap.h"
#include "mesh_clean.h"
#include "overlap.h"
#include "texture_sample.h"

namespace canopy {
namespace {

using Clock = std::chrono::steady_clock;
constexpr int kTile = 8;  // lattice cells per tile edge

// Default linear albedo where the file carries no colour at all (plain OBJ/STL).
constexpr float kDefaultWood[3] = {0.23f, 0.15f, 0.09f};
constexpr float kDefaultLeaf[3] = {0.12f, 0.30f, 0.06f};

// How each material is rasterised.
struct MaterialPlan {
  bool wood = false;
  bool alphaTest = false;  // MASK (or BLEND, tested at 0.5)
  float cutoff = 0.5f;
  const vox::MipChain* texture = nullptr;
  float factor[4] = {1, 1, 1, 1};
  const float* defaultColor = nullptr;  // non-null: no colour in the file
};

// --detail: the colour sum and touch count of one detail cell (the light cell's are in TileScratch).
struct DetailSum {
  double colour[3];
  uint64_t touches;
};

struct TileScratch {
  std::vector<uint64_t> any, wood;  // [cell * words + w]
  std::vector<double> colour;       // [cell * 3 + c]
  std::vector<uint64_t> touches;    // counted touches per cell
  std::vector<uint8_t> used;
  // --detail only: a block of k^3 DetailSums per touched cell, taken from `detail` at its first
  // touch (so memory follows the tile's touched cells, not its 512).
  std::vector<int32_t> block;     // [cell] -> its block, -1 none yet
  std::vector<DetailSum> detail;  // [block * k^3 + detail sub-cell]
};

// Texture-space frame of one triangle: the sample point's barycentric (s, t) are dot products of
// (point - a) with the dual basis (d1, d2) of the edges (b - a, c - a) within the triangle's plane.
// Dotting with in-plane vectors ignores the normal component, so (s, t) of a sub-cell centre are
// those of its orthogonal projection onto the plane.
struct BaryFrame {
  double d1[3] = {0, 0, 0}, d2[3] = {0, 0, 0};
  void init(const double a[3], const double b[3], const double c[3]) {
    double e1[3], e2[3];
    for (int k = 0; k < 3; ++k) { e1[k] = b[k] - a[k]; e2[k] = c[k] - a[k]; }
    auto dot = [](const double* x, const double* y) { return x[0] * y[0] + x[1] * y[1] + x[2] * y[2]; };
    const double a11 = dot(e1, e1), a12 = dot(e1, e2), a22 = dot(e2, e2);
    const double det = a11 * a22 - a12 * a12;
    const double inv = det > 0 ? 1.0 / det : 0.0;
    for (int k = 0; k < 3; ++k) {
      d1[k] = (a22 * e1[k] - a12 * e2[k]) * inv;
      d2[k] = (a11 * e2[k] - a12 * e1[k]) * inv;
    }
  }
  // Barycentric weights of the projection of q (relative to a), clamped into the triangle.
  void weights(const double q[3], double w[3]) const {
    double s = q[0] * d1[0] + q[1] * d1[1] + q[2] * d1[2];
    double t = q[0] * d2[0] + q[1] * d2[1] + q[2] * d2[2];
    s = s < 0 ? 0 : s;
    t = t < 0 ? 0 : t;
    if (s + t > 1) { const double u = s + t; s /= u; t /= u; }
    w[0] = 1 - s - t;
    w[1] = s;
    w[2] = t;
  }
};

// What every tile task reads: the mesh in fine-grid coordinates, its materials, the grid's sizes.
struct Raster {
  const mesh::Mesh* mesh = nullptr;
  std::vector<vox::MipChain> mips;        // plans point into it
  std::vector<MaterialPlan> plans;        // per material
  std::vector<std::array<double, 9>> fv;  // per triangle: its vertices in fine-grid units
  int N = 0, S = 0;                       // lattice cells per axis, sub-cells per cell per axis
  int k = 1, m = 0;                       // detail factor (1: none), sub-cells per detail cell per axis
  int words = 0;                          // 64-bit words of an S^3 bitmask
  int64_t F = 0, tileFine = 0, tilesPerAxis = 0;
  std::vector<int> cellOf, subOf, detOf;  // fine offset in a tile -> its cell, sub-cell, detail sub-block
};

// One tile: its first lattice cell (tc * kTile) and its fine-grid box [f0, f1).
struct TileBox {
  int64_t tc[3], f0[3], f1[3];
};

struct TouchCounts {
  uint64_t touches = 0, rejected = 0, exact = 0;
};

// The fine cells [a, b] along axis k that a triangle's closed bounding box meets.
void cellRange(const std::array<double, 9>& f, int k, int64_t F, int64_t& a, int64_t& b) {
  const double mn = std::min({f[size_t(k)], f[size_t(3 + k)], f[size_t(6 + k)]});
  const double mx = std::max({f[size_t(k)], f[size_t(3 + k)], f[size_t(6 + k)]});
  a = std::max<int64_t>(0, int64_t(std::ceil(mn)) - 1);  // closed boxes touching at a face count
  b = std::min<int64_t>(F - 1, int64_t(std::floor(mx)));
}

// Removes degenerate and duplicate faces (unless told not to); throws if none is left.
void cleanMesh(mesh::Mesh& mesh, const VoxelizeOptions& opt, const std::string& name, VoxelizeStats& st) {
  st.inputTriangles = mesh.triangles.size();
  if (mesh.triangles.empty()) throw invalidInput(name + ": the mesh has no triangles");
  mesh::requireFinite(mesh, name);
  const auto t0 = Clock::now();
  if (opt.clean) {
    const mesh::CleanStats cs = mesh::removeDegenerateAndDuplicateFaces(mesh);
    st.degenerateRemoved = cs.degenerate;
    st.duplicatesRemoved = cs.duplicate;
  }
  st.secondsClean = secondsSince(t0);
  if (mesh.triangles.empty())
    throw invalidInput(name + ": all " + std::to_string(st.inputTriangles) +
                       " triangles are degenerate (zero area)");
  st.triangles = mesh.triangles.size();
}

// The lattice frame: the bounding cube centred, one fine sub-cell inside cells 1..N-2. Sets the
// fine cell size hFine and the fine grid's corner.
LatticeFrame latticeFrame(const mesh::Mesh& mesh, int N, int S, const std::string& name, double& hFine,
                          double corner0[3]) {
  const int64_t F = int64_t(N) * S;  // fine cells per axis
  double lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
  for (const auto& t : mesh.triangles)
    for (const auto& p : t.p)
      for (int k = 0; k < 3; ++k) { lo[k] = std::min(lo[k], p[k]); hi[k] = std::max(hi[k], p[k]); }
  double extent = 0;
  for (int k = 0; k < 3; ++k) extent = std::max(extent, hi[k] - lo[k]);
  if (!(extent > 0) || !std::isfinite(extent))
    throw invalidInput(name + ": mesh extent is zero or not representable");
  hFine = extent / double((N - 2) * S - 2);
  LatticeFrame frame;
  for (int k = 0; k < 3; ++k) corner0[k] = 0.5 * (lo[k] + hi[k]) - 0.5 * double(F) * hFine;
  frame.resolution = N;
  frame.voxelSize = hFine * S;
  for (int k = 0; k < 3; ++k) frame.origin[k] = corner0[k] + 0.5 * hFine * S;
  return frame;
}

// The detail lattice's frame: k cells per lattice cell per axis, the same box.
LatticeFrame detailFrameOf(const LatticeFrame& light, int k) {
  LatticeFrame d;
  d.resolution = light.resolution * k;
  d.voxelSize = light.voxelSize / k;
  for (int a = 0; a < 3; ++a) d.origin[a] = light.origin[a] - 0.5 * light.voxelSize + 0.5 * d.voxelSize;
  return d;
}

// Materials: wood or leaf, alpha test, colour source. Fills R.mips and R.plans; counts wood and
// alpha-tested triangles.
void planMaterials(const mesh::Mesh& mesh, const std::string& woodPattern, const std::string& name, Raster& R,
                   VoxelizeStats& st) {
  const std::vector<bool> woodMat = classifyWood(mesh.materials, woodPattern);
  R.mips.resize(mesh.textures.size());
  tbb::parallel_for(size_t(0), R.mips.size(), [&](size_t i) { R.mips[i] = vox::buildMips(mesh.textures[i]); });
  R.plans.assign(mesh.materials.size(), MaterialPlan());
  for (size_t i = 0; i < R.plans.size(); ++i) {
    const auto& m = mesh.materials[i];
    MaterialPlan& p = R.plans[i];
    p.wood = woodMat[i];
    p.alphaTest = m.alphaMode != mesh::AlphaMode::Opaque;
    p.cutoff = m.alphaMode == mesh::AlphaMode::Mask ? m.alphaCutoff : 0.5f;
    if (m.baseColorTexture >= 0) p.texture = &R.mips[size_t(m.baseColorTexture)];
    for (int c = 0; c < 4; ++c) p.factor[c] = m.baseColorFactor[size_t(c)];
    if (!m.hasColor && !mesh.hasTriangleColors) p.defaultColor = p.wood ? kDefaultWood : kDefaultLeaf;
  }
  for (const auto& t : mesh.triangles) {
    if (t.material < 0 || size_t(t.material) >= R.plans.size())
      throw invalidInput(name + ": triangle references missing material " + std::to_string(t.material));
    st.woodTriangles += R.plans[size_t(t.material)].wood;
    st.maskedTriangles += R.plans[size_t(t.material)].alphaTest;
  }
}

// The fine-grid vertices and the grid's sizes and per-offset lookup tables.
void setupGrid(const mesh::Mesh& mesh, int N, int S, int k, double hFine, const double corner0[3], Raster& R) {
  R.mesh = &mesh;
  R.N = N;
  R.S = S;
  R.k = k;
  R.m = S / k;
  R.words = (S * S * S + 63) / 64;
  R.F = int64_t(N) * S;
  R.tileFine = int64_t(kTile) * S;
  R.tilesPerAxis = (N + kTile - 1) / kTile;
  const size_t nt = mesh.triangles.size();
  R.fv.resize(nt);
  tbb::parallel_for(size_t(0), nt, [&](size_t i) {
    for (int v = 0; v < 3; ++v)
      for (int a = 0; a < 3; ++a)
        R.fv[i][size_t(v * 3 + a)] = (mesh.triangles[i].p[size_t(v)][size_t(a)] - corner0[a]) / hFine;
  });
  for (int64_t l = 0; l < R.tileFine; ++l) {
    R.cellOf.push_back(int(l / S));
    R.subOf.push_back(int(l % S));
    R.detOf.push_back(int(l % S) / R.m);
  }
}

// Bins triangles into the tiles their fine bounding box meets (tile key -> triangles in file order).
std::unordered_map<int64_t, std::vector<uint32_t>> binTriangles(const Raster& R) {
  std::unordered_map<int64_t, std::vector<uint32_t>> bins;
  for (size_t i = 0; i < R.fv.size(); ++i) {
    int64_t a[3], b[3];
    for (int k = 0; k < 3; ++k) {
      cellRange(R.fv[i], k, R.F, a[k], b[k]);
      a[k] /= R.tileFine;
      b[k] /= R.tileFine;
    }
    for (int64_t x = a[0]; x <= b[0]; ++x)
      for (int64_t y = a[1]; y <= b[1]; ++y)
        for (int64_t z = a[2]; z <= b[2]; ++z)
          bins[(x * R.tilesPerAxis + y) * R.tilesPerAxis + z].push_back(uint32_t(i));
  }
  return bins;
}

// Per-triangle state of the rasteriser: local coordinates relative to the integer floor of the
// triangle's minimum (exact), the overlap test's setup, the texture frame and mip level.
struct TriangleSetup {
  double o[3], a[3], b[3], c[3];
  vox::TriBoxSetup box;
  BaryFrame bary;
  const mesh::Texture* level = nullptr;
};

void setupTriangle(const Raster& R, uint32_t triIndex, TriangleSetup& t) {
  const mesh::Triangle& tri = R.mesh->triangles[triIndex];
  const MaterialPlan& plan = R.plans[size_t(tri.material)];
  const auto& f = R.fv[triIndex];
  double M = 0;
  for (int k = 0; k < 3; ++k) {
    t.o[k] = std::floor(std::min({f[size_t(k)], f[size_t(3 + k)], f[size_t(6 + k)]}));
    t.a[k] = f[size_t(k)] - t.o[k];
    t.b[k] = f[size_t(3 + k)] - t.o[k];
    t.c[k] = f[size_t(6 + k)] - t.o[k];
    M = std::max({M, t.a[k], t.b[k], t.c[k]});
  }
  M += 2;
  int sign[3];
  vox::exactNormalSigns(t.a, t.b, t.c, sign);
  t.box = vox::setupTriBox(t.a, t.b, t.c, M, sign);
  t.level = nullptr;
  if (plan.texture) {
    t.bary.init(t.a, t.b, t.c);
    const double uvArea = 0.5 * std::fabs(double(tri.uv[1][0] - tri.uv[0][0]) * (tri.uv[2][1] - tri.uv[0][1]) -
                                          double(tri.uv[2][0] - tri.uv[0][0]) * (tri.uv[1][1] - tri.uv[0][1]));
    const double fineArea = 0.5 * std::sqrt(t.box.n[0] * t.box.n[0] + t.box.n[1] * t.box.n[1] + t.box.n[2] * t.box.n[2]);
    t.level = &plan.texture->levels[size_t(vox::mipLevel(*plan.texture, uvArea, fineArea))];
  }
}

// The material at a touched sub-cell (local corner p): false where the alpha test drops it, else
// its linear colour in rgb. The sample point is the sub-cell centre projected onto the triangle's
// plane, clamped into the triangle.
bool shadeTouch(const Raster& R, const mesh::Triangle& tri, const TriangleSetup& t, const double p[3], float rgb[3]) {
  const MaterialPlan& plan = R.plans[size_t(tri.material)];
  rgb[0] = rgb[1] = rgb[2] = 1;
  if (plan.defaultColor) {
    if (plan.alphaTest && plan.factor[3] < plan.cutoff) return false;
    for (int k = 0; k < 3; ++k) rgb[k] = plan.defaultColor[k];
    return true;
  }
  if (plan.texture) {
    const double q[3] = {p[0] + 0.5 - t.a[0], p[1] + 0.5 - t.a[1], p[2] + 0.5 - t.a[2]};
    double w[3];
    t.bary.weights(q, w);
    const float u = float(w[0] * tri.uv[0][0] + w[1] * tri.uv[1][0] + w[2] * tri.uv[2][0]);
    const float v = float(w[0] * tri.uv[0][1] + w[1] * tri.uv[1][1] + w[2] * tri.uv[2][1]);
    const vox::Footprint fp = vox::footprint(*t.level, u, v);
    const float alpha = plan.alphaTest ? vox::sampleAlpha(*t.level, fp) : 1.0f;
    if (plan.alphaTest && alpha * plan.factor[3] < plan.cutoff) return false;
    vox::sampleColor(*t.level, fp, rgb);
  } else if (plan.alphaTest && plan.factor[3] < plan.cutoff) {
    return false;
  }
  for (int k = 0; k < 3; ++k)
    rgb[k] *= plan.factor[k] * (R.mesh->hasTriangleColors ? tri.color[size_t(k)] : 1.0f);
  return true;
}

// Records a counted touch of fine cell g (tile-local offsets from f0) in its lattice cell and,
// with --detail, in its detail cell.
void recordTouch(const Raster& R, TileScratch& s, const int64_t g[3], const int64_t f0[3], bool wood,
                 const float rgb[3]) {
  const size_t l[3] = {size_t(g[0] - f0[0]), size_t(g[1] - f0[1]), size_t(g[2] - f0[2])};
  const int cell = (R.cellOf[l[0]] * kTile + R.cellOf[l[1]]) * kTile + R.cellOf[l[2]];
  const int bit = (R.subOf[l[0]] * R.S + R.subOf[l[1]]) * R.S + R.subOf[l[2]];
  const size_t wi = size_t(cell) * size_t(R.words) + size_t(bit >> 6);
  s.any[wi] |= uint64_t(1) << (bit & 63);
  if (wood) s.wood[wi] |= uint64_t(1) << (bit & 63);
  for (int k = 0; k < 3; ++k) s.colour[size_t(cell) * 3 + size_t(k)] += rgb[k];
  ++s.touches[size_t(cell)];
  s.used[size_t(cell)] = 1;
  if (R.k == 1) return;
  const size_t k3 = size_t(R.k) * size_t(R.k) * size_t(R.k);
  int32_t& b = s.block[size_t(cell)];
  if (b < 0) {
    b = int32_t(s.detail.size() / k3);
    s.detail.resize(s.detail.size() + k3);  // value-initialised: zero sums
  }
  const int d = (R.detOf[l[0]] * R.k + R.detOf[l[1]]) * R.k + R.detOf[l[2]];
  DetailSum& ds = s.detail[size_t(b) * k3 + size_t(d)];
  for (int k = 0; k < 3; ++k) ds.colour[k] += rgb[k];
  ++ds.touches;
}

// Rasterises one triangle into a tile's scratch: every fine cell of the tile whose closed box
// meets the triangle and passes the material's alpha test is recorded.
void rasteriseTriangle(const Raster& R, uint32_t triIndex, const TileBox& tile, TileScratch& s, TouchCounts& n) {
  const mesh::Triangle& tri = R.mesh->triangles[triIndex];
  int64_t lo3[3], hi3[3];
  for (int k = 0; k < 3; ++k) {
    cellRange(R.fv[triIndex], k, R.F, lo3[k], hi3[k]);
    lo3[k] = std::max(lo3[k], tile.f0[k]);
    hi3[k] = std::min(hi3[k], tile.f1[k] - 1);
    if (lo3[k] > hi3[k]) return;
  }
  TriangleSetup t;
  setupTriangle(R, triIndex, t);
  const vox::TriBoxSetup& setup = t.box;
  // Iterate columns along the normal's dominant axis; the plane bounds each column.
  int A = 0;
  for (int k = 1; k < 3; ++k)
    if (std::fabs(setup.n[k]) > std::fabs(setup.n[A])) A = k;
  const int B = (A + 1) % 3, C = (A + 2) % 3;
  const double nv = setup.n[0] * t.a[0] + setup.n[1] * t.a[1] + setup.n[2] * t.a[2];
  const int q = (A + 1) % 3;  // the projection onto the (B, C) plane in overlap.h's order
  for (int64_t xb = lo3[B]; xb <= hi3[B]; ++xb)
    for (int64_t xc = lo3[C]; xc <= hi3[C]; ++xc) {
      const double pb = double(xb) - t.o[B], pc = double(xc) - t.o[C];
      // The column's square must meet the projected triangle (conservative by the band).
      bool outside = false;
      for (int e = 0; e < 3; ++e)
        outside |= setup.ne[q][e][0] * pb + setup.ne[q][e][1] * pc + setup.de[q][e] < -setup.tolEdge;
      if (outside) continue;
      // Cells of the column that the plane can reach: [amin, amax] over the square.
      double amin = INFINITY, amax = -INFINITY;
      if (setup.n[A] == 0) { amin = -INFINITY; amax = INFINITY; }  // degenerate: whole range
      else for (int cb = 0; cb < 2; ++cb)
        for (int cc = 0; cc < 2; ++cc) {
          const double av = (nv - setup.n[B] * (pb + cb) - setup.n[C] * (pc + cc)) / setup.n[A];
          amin = std::min(amin, av);
          amax = std::max(amax, av);
        }
      const double slack = 1e-6;  // rounding of amin/amax; the exact test decides
      const int64_t a0 = std::isfinite(amin) ? std::max(lo3[A], int64_t(std::ceil(amin + t.o[A] - slack)) - 1) : lo3[A];
      const int64_t a1 = std::isfinite(amax) ? std::min(hi3[A], int64_t(std::floor(amax + t.o[A] + slack))) : hi3[A];
      for (int64_t xa = a0; xa <= a1; ++xa) {
        int64_t g[3];
        g[A] = xa; g[B] = xb; g[C] = xc;
        const double p[3] = {double(g[0]) - t.o[0], double(g[1]) - t.o[1], double(g[2]) - t.o[2]};
        const vox::Overlap ov = vox::testTriBox(setup, p);
        if (ov == vox::Overlap::No) continue;
        if (ov == vox::Overlap::Ambiguous) {
          ++n.exact;
          if (!vox::exactTriBoxOverlap(t.a, t.b, t.c, p)) continue;
        }
        ++n.touches;
        float rgb[3];
        if (!shadeTouch(R, tri, t, p, rgb)) { ++n.rejected; continue; }
        recordTouch(R, s, g, tile.f0, R.plans[size_t(tri.material)].wood, rgb);
      }
    }
}

// Touched sub-cells of each of a cell's k^3 blocks of m^3 sub-cells (m = S / k), from its S^3
// bitmask (bit (x S + y) S + z is sub-cell (x, y, z)); counts[(bx k + by) k + bz]. k = 1 is the
// whole cell (its words' popcounts: bits past S^3 are never set). Otherwise each z row of a block
// is m consecutive bits (m <= 16), possibly across two words.
void blockCounts(const uint64_t* mask, int S, int k, int* counts) {
  if (k == 1) {
    counts[0] = 0;
    for (int w = 0; w < (S * S * S + 63) / 64; ++w) counts[0] += __builtin_popcountll(mask[w]);
    return;
  }
  const int m = S / k;
  std::fill(counts, counts + k * k * k, 0);
  for (int x = 0; x < S; ++x)
    for (int y = 0; y < S; ++y) {
      int* row = counts + ((x / m) * k + y / m) * k;
      for (int bz = 0; bz < k; ++bz) {
        const int first = (x * S + y) * S + bz * m, word = first >> 6, shift = first & 63;
        uint64_t bits = mask[word] >> shift;
        if (shift + m > 64) bits |= mask[word + 1] << (64 - shift);
        row[bz] += __builtin_popcountll(bits & ((uint64_t(1) << m) - 1));
      }
    }
}

// A cell's values (a lattice cell or a detail cell alike) from its touched and wood-touched
// sub-cell counts out of subCells, and the colour sum of its touches.
LatticeCell cellValues(const int64_t ijk[3], int count, int woodCount, int subCells, const double colour[3],
                       uint64_t touches) {
  LatticeCell lc;
  lc.i = int32_t(ijk[0]);
  lc.j = int32_t(ijk[1]);
  lc.k = int32_t(ijk[2]);
  lc.density = float(count) / float(subCells);
  lc.wood = float(woodCount) / float(count);
  const double n = double(touches);
  for (int a = 0; a < 3; ++a) lc.albedo[a] = float(colour[a] / n);
  return lc;
}

// Averages a tile's sub-cells into its lattice cells and, with --detail, its detail cells.
void averageTile(const Raster& R, const TileScratch& s, const TileBox& tile, std::vector<LatticeCell>& out,
                 std::vector<LatticeCell>& detailOut) {
  const int k = R.k, k3 = k * k * k;
  std::vector<int> counts(size_t(k3), 0), woodCounts(size_t(k3), 0);
  for (int cell = 0; cell < kTile * kTile * kTile; ++cell) {
    if (!s.used[size_t(cell)]) continue;
    const uint64_t* any = &s.any[size_t(cell) * size_t(R.words)];
    const uint64_t* wood = &s.wood[size_t(cell) * size_t(R.words)];
    const int64_t ijk[3] = {tile.tc[0] * kTile + cell / (kTile * kTile), tile.tc[1] * kTile + (cell / kTile) % kTile,
                            tile.tc[2] * kTile + cell % kTile};
    int count, woodCount;
    blockCounts(any, R.S, 1, &count);
    blockCounts(wood, R.S, 1, &woodCount);
    out.push_back(cellValues(ijk, count, woodCount, R.S * R.S * R.S, &s.colour[size_t(cell) * 3],
                             s.touches[size_t(cell)]));
    if (k == 1) continue;
    blockCounts(any, R.S, k, counts.data());
    blockCounts(wood, R.S, k, woodCounts.data());
    const DetailSum* sums = &s.detail[size_t(s.block[size_t(cell)]) * size_t(k3)];
    for (int d = 0; d < k3; ++d) {
      if (counts[size_t(d)] == 0) continue;
      const int64_t dijk[3] = {ijk[0] * k + d / (k * k), ijk[1] * k + (d / k) % k, ijk[2] * k + d % k};
      detailOut.push_back(cellValues(dijk, counts[size_t(d)], woodCounts[size_t(d)], R.m * R.m * R.m,
                                     sums[d].colour, sums[d].touches));
    }
  }
}

TileScratch makeScratch(const Raster& R) {
  const size_t cellsPerTile = size_t(kTile) * kTile * kTile;
  TileScratch s;
  s.any.assign(cellsPerTile * size_t(R.words), 0);
  s.wood.assign(s.any.size(), 0);
  s.colour.assign(cellsPerTile * 3, 0.0);
  s.touches.assign(cellsPerTile, 0);
  s.used.assign(cellsPerTile, 0);
  if (R.k > 1) s.block.assign(cellsPerTile, -1);
  return s;
}

void clearScratch(TileScratch& s) {
  std::fill(s.any.begin(), s.any.end(), 0);
  std::fill(s.wood.begin(), s.wood.end(), 0);
  std::fill(s.colour.begin(), s.colour.end(), 0.0);
  std::fill(s.touches.begin(), s.touches.end(), 0);
  std::fill(s.used.begin(), s.used.end(), 0);
  std::fill(s.block.begin(), s.block.end(), -1);
  s.detail.clear();
}

TileBox tileBox(const Raster& R, int64_t key) {
  TileBox t;
  t.tc[0] = key / (R.tilesPerAxis * R.tilesPerAxis);
  t.tc[1] = (key / R.tilesPerAxis) % R.tilesPerAxis;
  t.tc[2] = key % R.tilesPerAxis;
  for (int a = 0; a < 3; ++a) {
    t.f0[a] = t.tc[a] * R.tileFine;
    t.f1[a] = std::min(R.F, t.f0[a] + R.tileFine);
  }
  return t;
}

// Concatenates per-tile cells and sorts them by (i, j, k).
std::vector<LatticeCell> gatherCells(std::vector<std::vector<LatticeCell>>& perTile) {
  size_t total = 0;
  for (auto& v : perTile) total += v.size();
  std::vector<LatticeCell> cells;
  cells.reserve(total);
  for (auto& v : perTile) {
    cells.insert(cells.end(), v.begin(), v.end());
    std::vector<LatticeCell>().swap(v);
  }
  std::sort(cells.begin(), cells.end(), [](const LatticeCell& x, const LatticeCell& y) {
    return std::tie(x.i, x.j, x.k) < std::tie(y.i, y.j, y.k);
  });
  return cells;
}

// Rasterises every tile (in parallel; triangles in file order within a tile) and averages them.
void rasteriseTiles(const Raster& R, const std::unordered_map<int64_t, std::vector<uint32_t>>& bins,
                    const std::vector<int64_t>& tiles, VoxelizeResult& result) {
  tbb::enumerable_thread_specific<TileScratch> scratch([&] { return makeScratch(R); });
  std::vector<std::vector<LatticeCell>> tileCells(tiles.size()), tileDetail(R.k > 1 ? tiles.size() : 0);
  std::vector<LatticeCell> noDetail;
  std::atomic<uint64_t> fineTouches{0}, alphaRejected{0}, exactTests{0};
  Progress progress("voxelize", int64_t(tiles.size()));
  tbb::parallel_for(tbb::blocked_range<size_t>(0, tiles.size(), 1), [&](const tbb::blocked_range<size_t>& r) {
    TileScratch& s = scratch.local();
    for (size_t ti = r.begin(); ti != r.end(); ++ti) {
      const TileBox tile = tileBox(R, tiles[ti]);
      clearScratch(s);
      TouchCounts n;
      for (uint32_t triIndex : bins.at(tiles[ti])) rasteriseTriangle(R, triIndex, tile, s, n);
      averageTile(R, s, tile, tileCells[ti], R.k > 1 ? tileDetail[ti] : noDetail);
      fineTouches += n.touches;
      alphaRejected += n.rejected;
      exactTests += n.exact;
      progress.add(1);
    }
  });
  progress.done();
  result.cells = gatherCells(tileCells);
  result.detailCells = gatherCells(tileDetail);
  result.stats.fineTouches = fineTouches;
  result.stats.alphaRejected = alphaRejected;
  result.stats.exactTests = exactTests;
}

// Refuses an empty lattice; fills the density statistics.
void finishStats(VoxelizeResult& result, const std::string& name) {
  VoxelizeStats& st = result.stats;
  st.occupiedCells = result.cells.size();
  if (result.cells.empty()) {
    // An empty lattice is no model: refuse it here rather than two tools later.
    const std::string n = std::to_string(st.triangles);
    throw invalidInput(name + ": no cell is occupied (" +
                       (st.fineTouches > 0 && st.alphaRejected == st.fineTouches
                            ? "all " + n + " triangles were removed by the alpha test)"
                            : "none of the " + n + " triangles touches a sub-cell)"));
  }
  double sumD = 0, sumW = 0;
  for (const auto& c : result.cells) {
    sumD += c.density;
    sumW += double(c.density) * c.wood;
  }
  st.totalDensity = sumD;
  st.woodFraction = sumD > 0 ? sumW / sumD : 0;
  st.detailOccupiedCells = result.detailCells.size();
  st.detailTotalDensity = 0;
  for (const auto& c : result.detailCells) st.detailTotalDensity += c.density;
}

}  // namespace

void validateOptions(const VoxelizeOptions& o) {
  if (o.resolution < kMinResolution || o.resolution > kMaxResolution)
    throw usageError("--resolution " + std::to_string(o.resolution) + " is outside " +
                     std::to_string(kMinResolution) + ".." + std::to_string(kMaxResolution));
  if (o.supersample < 1 || o.supersample > kMaxSupersample)
    throw usageError("--supersample " + std::to_string(o.supersample) + " is outside 1.." +
                     std::to_string(kMaxSupersample));
  if (int64_t(o.resolution) * o.supersample > kMaxFineResolution)
    throw usageError("--resolution x --supersample = " +
                     std::to_string(int64_t(o.resolution) * o.supersample) +
                     " fine cells per axis exceeds " + std::to_string(kMaxFineResolution));
  if (o.detail != 0) {
    const std::string d = "--detail " + std::to_string(o.detail), r = std::to_string(o.resolution);
    if (o.detail <= o.resolution) throw usageError(d + " is not finer than --resolution " + r);
    if (o.detail > kMaxResolution)
      throw usageError(d + " exceeds " + std::to_string(kMaxResolution) + " cells per axis (the lattice reader's limit)");
    const int k = o.detail / o.resolution;
    if (o.detail % o.resolution != 0 || k > kMaxDetailFactor || (k & (k - 1)) != 0)
      throw usageError(d + " is not --resolution " + r + " times 2, 4, 8 or 16");
    if (o.supersample % k != 0)
      throw usageError("--supersample " + std::to_string(o.supersample) + " must be a multiple of the detail factor " +
                       std::to_string(k));
  }
  if (o.detail == 0 && !o.detailOutput.empty()) throw usageError("--detail-output needs --detail");
  if (o.meshIndex < -1) throw usageError("--mesh " + std::to_string(o.meshIndex) + " must be a mesh index >= 0");
  try {
    std::regex re(o.woodPattern, std::regex::ECMAScript | std::regex::icase);
  } catch (const std::regex_error& e) {
    throw usageError("--wood-pattern '" + o.woodPattern + "' is not a valid regular expression");
  }
}

int detailFactor(const VoxelizeOptions& o) { return o.detail > 0 ? o.detail / o.resolution : 1; }

std::string detailOutputPath(const VoxelizeOptions& o) {
  if (o.detail == 0) return "";
  std::string path = o.detailOutput;
  const std::string suffix = ".density.vdb";
  if (path.empty() && o.output.empty()) return "";
  if (path.empty()) {
    if (o.output.size() < suffix.size() || o.output.compare(o.output.size() - suffix.size(), suffix.size(), suffix) != 0)
      throw usageError("--detail needs --detail-output FILE when -o (" + o.output + ") does not end in " + suffix);
    path = o.output.substr(0, o.output.size() - suffix.size()) + ".detail.vdb";
  }
  std::error_code e1, e2;
  if (!o.output.empty() && (path == o.output || std::filesystem::weakly_canonical(path, e1) ==
                                                    std::filesystem::weakly_canonical(o.output, e2)))
    throw usageError("--detail-output " + path + " is the -o file");
  return path;
}

std::vector<bool> classifyWood(const std::vector<mesh::Material>& materials,
                               const std::string& pattern) {
  const std::regex re(pattern, std::regex::ECMAScript | std::regex::icase);
  std::vector<bool> wood;
  for (const auto& m : materials) wood.push_back(std::regex_search(m.name, re));
  return wood;
}

VoxelizeResult voxelizeMesh(mesh::Mesh mesh, const VoxelizeOptions& opt, const std::string& name) {
  validateOptions(opt);
  VoxelizeResult result;
  VoxelizeStats& st = result.stats;
  cleanMesh(mesh, opt, name, st);
  const auto t0 = Clock::now();
  const int N = opt.resolution, S = opt.supersample, k = detailFactor(opt);
  double hFine, corner0[3];
  result.frame = latticeFrame(mesh, N, S, name, hFine, corner0);
  if (k > 1) {
    result.detailFactor = k;
    result.detailFrame = detailFrameOf(result.frame, k);
  }
  Raster R;
  planMaterials(mesh, opt.woodPattern, name, R, st);
  setupGrid(mesh, N, S, k, hFine, corner0, R);
  const auto bins = binTriangles(R);
  std::vector<int64_t> tiles;
  tiles.reserve(bins.size());
  for (auto& kv : bins) tiles.push_back(kv.first);
  std::sort(tiles.begin(), tiles.end());
  st.occupiedTiles = tiles.size();
  rasteriseTiles(R, bins, tiles, result);
  finishStats(result, name);
  st.secondsVoxelize = secondsSince(t0);
  return result;
}

}  // namespace canopy
