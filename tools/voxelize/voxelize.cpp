// voxelize.cpp: the rasteriser (see voxelize.h for what it computes).
//
// Pipeline: bin triangles into tiles of 8^3 lattice cells (only tiles a triangle's bounding box
// meets), then process tiles in parallel. Within a tile each lattice cell owns two bitmasks of its
// supersample^3 fine sub-cells (touched by counted geometry; touched by wood) and a colour sum.
// Triangles are rasterised in file order, so sums and results are identical at any thread count.
#include "voxelize.h"

#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
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

struct TileScratch {
  std::vector<uint64_t> any, wood;  // [cell * words + w]
  std::vector<double> colour;       // [cell * 3 + c]
  std::vector<uint64_t> touches;    // counted touches per cell
  std::vector<uint8_t> used;
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
  if (o.meshIndex < -1) throw usageError("--mesh " + std::to_string(o.meshIndex) + " must be a mesh index >= 0");
  try {
    std::regex re(o.woodPattern, std::regex::ECMAScript | std::regex::icase);
  } catch (const std::regex_error& e) {
    throw usageError("--wood-pattern '" + o.woodPattern + "' is not a valid regular expression");
  }
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
  st.inputTriangles = mesh.triangles.size();
  if (mesh.triangles.empty()) throw invalidInput(name + ": the mesh has no triangles");
  mesh::requireFinite(mesh, name);

  auto t0 = Clock::now();
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
  t0 = Clock::now();

  // ---- Lattice frame: bounding cube centred, one fine sub-cell inside cells 1..N-2 ----------
  const int N = opt.resolution, S = opt.supersample;
  const int64_t F = int64_t(N) * S;  // fine cells per axis
  double lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
  for (const auto& t : mesh.triangles)
    for (const auto& p : t.p)
      for (int k = 0; k < 3; ++k) { lo[k] = std::min(lo[k], p[k]); hi[k] = std::max(hi[k], p[k]); }
  double extent = 0;
  for (int k = 0; k < 3; ++k) extent = std::max(extent, hi[k] - lo[k]);
  if (!(extent > 0) || !std::isfinite(extent))
    throw invalidInput(name + ": mesh extent is zero or not representable");
  const double hFine = extent / double((N - 2) * S - 2);
  double corner0[3];
  for (int k = 0; k < 3; ++k) corner0[k] = 0.5 * (lo[k] + hi[k]) - 0.5 * double(F) * hFine;
  result.frame.resolution = N;
  result.frame.voxelSize = hFine * S;
  for (int k = 0; k < 3; ++k) result.frame.origin[k] = corner0[k] + 0.5 * hFine * S;

  // ---- Materials -----------------------------------------------------------------------------
  const std::vector<bool> woodMat = classifyWood(mesh.materials, opt.woodPattern);
  std::vector<vox::MipChain> mips(mesh.textures.size());
  tbb::parallel_for(size_t(0), mips.size(), [&](size_t i) { mips[i] = vox::buildMips(mesh.textures[i]); });
  std::vector<MaterialPlan> plans(mesh.materials.size());
  for (size_t i = 0; i < plans.size(); ++i) {
    const auto& m = mesh.materials[i];
    MaterialPlan& p = plans[i];
    p.wood = woodMat[i];
    p.alphaTest = m.alphaMode != mesh::AlphaMode::Opaque;
    p.cutoff = m.alphaMode == mesh::AlphaMode::Mask ? m.alphaCutoff : 0.5f;
    if (m.baseColorTexture >= 0) p.texture = &mips[size_t(m.baseColorTexture)];
    for (int c = 0; c < 4; ++c) p.factor[c] = m.baseColorFactor[size_t(c)];
    if (!m.hasColor && !mesh.hasTriangleColors) p.defaultColor = p.wood ? kDefaultWood : kDefaultLeaf;
  }
  for (const auto& t : mesh.triangles) {
    if (t.material < 0 || size_t(t.material) >= plans.size())
      throw invalidInput(name + ": triangle references missing material " + std::to_string(t.material));
    st.woodTriangles += plans[size_t(t.material)].wood;
    st.maskedTriangles += plans[size_t(t.material)].alphaTest;
  }

  // ---- Fine-grid vertices and tile binning ---------------------------------------------------
  const size_t nt = mesh.triangles.size();
  std::vector<std::array<double, 9>> fv(nt);
  tbb::parallel_for(size_t(0), nt, [&](size_t i) {
    for (int v = 0; v < 3; ++v)
      for (int k = 0; k < 3; ++k)
        fv[i][size_t(v * 3 + k)] = (mesh.triangles[i].p[size_t(v)][size_t(k)] - corner0[k]) / hFine;
  });
  const int64_t tileFine = int64_t(kTile) * S;
  const int64_t tilesPerAxis = (N + kTile - 1) / kTile;
  auto cellRange = [&](const std::array<double, 9>& f, int k, int64_t& a, int64_t& b) {
    const double mn = std::min({f[size_t(k)], f[size_t(3 + k)], f[size_t(6 + k)]});
    const double mx = std::max({f[size_t(k)], f[size_t(3 + k)], f[size_t(6 + k)]});
    a = std::max<int64_t>(0, int64_t(std::ceil(mn)) - 1);  // closed boxes touching at a face count
    b = std::min<int64_t>(F - 1, int64_t(std::floor(mx)));
  };
  std::unordered_map<int64_t, std::vector<uint32_t>> bins;
  for (size_t i = 0; i < nt; ++i) {
    int64_t a[3], b[3];
    for (int k = 0; k < 3; ++k) {
      cellRange(fv[i], k, a[k], b[k]);
      a[k] /= tileFine;
      b[k] /= tileFine;
    }
    for (int64_t x = a[0]; x <= b[0]; ++x)
      for (int64_t y = a[1]; y <= b[1]; ++y)
        for (int64_t z = a[2]; z <= b[2]; ++z)
          bins[(x * tilesPerAxis + y) * tilesPerAxis + z].push_back(uint32_t(i));
  }
  std::vector<int64_t> tiles;
  tiles.reserve(bins.size());
  for (auto& kv : bins) tiles.push_back(kv.first);
  std::sort(tiles.begin(), tiles.end());
  st.occupiedTiles = tiles.size();

  // ---- Rasterise tiles in parallel -------------------------------------------------------------
  const int sub3 = S * S * S;
  const int words = (sub3 + 63) / 64;
  const int cellsPerTile = kTile * kTile * kTile;
  tbb::enumerable_thread_specific<TileScratch> scratch([&] {
    TileScratch s;
    s.any.assign(size_t(cellsPerTile) * size_t(words), 0);
    s.wood.assign(s.any.size(), 0);
    s.colour.assign(size_t(cellsPerTile) * 3, 0.0);
    s.touches.assign(size_t(cellsPerTile), 0);
    s.used.assign(size_t(cellsPerTile), 0);
    return s;
  });
  std::vector<std::vector<LatticeCell>> tileCells(tiles.size());
  std::vector<int> cellOf(static_cast<size_t>(tileFine)), subOf(static_cast<size_t>(tileFine));  // fine offset -> cell, sub
  for (int64_t l = 0; l < tileFine; ++l) {
    cellOf[size_t(l)] = int(l / S);
    subOf[size_t(l)] = int(l % S);
  }
  std::atomic<uint64_t> fineTouches{0}, alphaRejected{0}, exactTests{0};
  Progress progress("voxelize", int64_t(tiles.size()));

  tbb::parallel_for(tbb::blocked_range<size_t>(0, tiles.size(), 1), [&](const tbb::blocked_range<size_t>& r) {
    TileScratch& s = scratch.local();
    for (size_t ti = r.begin(); ti != r.end(); ++ti) {
      const int64_t key = tiles[ti];
      const int64_t tc[3] = {key / (tilesPerAxis * tilesPerAxis), (key / tilesPerAxis) % tilesPerAxis,
                             key % tilesPerAxis};
      const int64_t f0[3] = {tc[0] * tileFine, tc[1] * tileFine, tc[2] * tileFine};
      const int64_t f1[3] = {std::min(F, f0[0] + tileFine), std::min(F, f0[1] + tileFine),
                             std::min(F, f0[2] + tileFine)};
      std::fill(s.any.begin(), s.any.end(), 0);
      std::fill(s.wood.begin(), s.wood.end(), 0);
      std::fill(s.colour.begin(), s.colour.end(), 0.0);
      std::fill(s.touches.begin(), s.touches.end(), 0);
      std::fill(s.used.begin(), s.used.end(), 0);
      uint64_t touchesHere = 0, rejectedHere = 0, exactHere = 0;

      for (uint32_t triIndex : bins.at(key)) {
        const mesh::Triangle& tri = mesh.triangles[triIndex];
        const MaterialPlan& plan = plans[size_t(tri.material)];
        const auto& f = fv[triIndex];
        // Local coordinates relative to the integer floor of the triangle's minimum (exact).
        double o[3], a[3], b[3], c[3], M = 0;
        for (int k = 0; k < 3; ++k) {
          o[k] = std::floor(std::min({f[size_t(k)], f[size_t(3 + k)], f[size_t(6 + k)]}));
          a[k] = f[size_t(k)] - o[k];
          b[k] = f[size_t(3 + k)] - o[k];
          c[k] = f[size_t(6 + k)] - o[k];
          M = std::max({M, a[k], b[k], c[k]});
        }
        M += 2;
        int sign[3];
        vox::exactNormalSigns(a, b, c, sign);
        const vox::TriBoxSetup setup = vox::setupTriBox(a, b, c, M, sign);
        BaryFrame bary;
        const mesh::Texture* level = nullptr;
        if (plan.texture) {
          bary.init(a, b, c);
          const double uvArea = 0.5 * std::fabs(double(tri.uv[1][0] - tri.uv[0][0]) * (tri.uv[2][1] - tri.uv[0][1]) -
                                                double(tri.uv[2][0] - tri.uv[0][0]) * (tri.uv[1][1] - tri.uv[0][1]));
          const double fineArea = 0.5 * std::sqrt(setup.n[0] * setup.n[0] + setup.n[1] * setup.n[1] + setup.n[2] * setup.n[2]);
          level = &plan.texture->levels[size_t(vox::mipLevel(*plan.texture, uvArea, fineArea))];
        }
        int64_t lo3[3], hi3[3];
        bool empty = false;
        for (int k = 0; k < 3; ++k) {
          cellRange(f, k, lo3[k], hi3[k]);
          lo3[k] = std::max(lo3[k], f0[k]);
          hi3[k] = std::min(hi3[k], f1[k] - 1);
          empty |= lo3[k] > hi3[k];
        }
        if (!empty) {
          // Iterate columns along the normal's dominant axis; the plane bounds each column.
          int A = 0;
          for (int k = 1; k < 3; ++k)
            if (std::fabs(setup.n[k]) > std::fabs(setup.n[A])) A = k;
          const int B = (A + 1) % 3, C = (A + 2) % 3;
          const double nv = setup.n[0] * a[0] + setup.n[1] * a[1] + setup.n[2] * a[2];
          const int q = (A + 1) % 3;  // the projection onto the (B, C) plane in overlap.h's order
          for (int64_t xb = lo3[B]; xb <= hi3[B]; ++xb)
            for (int64_t xc = lo3[C]; xc <= hi3[C]; ++xc) {
              const double pb = double(xb) - o[B], pc = double(xc) - o[C];
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
              const int64_t a0 = std::isfinite(amin) ? std::max(lo3[A], int64_t(std::ceil(amin + o[A] - slack)) - 1) : lo3[A];
              const int64_t a1 = std::isfinite(amax) ? std::min(hi3[A], int64_t(std::floor(amax + o[A] + slack))) : hi3[A];
              for (int64_t xa = a0; xa <= a1; ++xa) {
                int64_t g[3];
                g[A] = xa; g[B] = xb; g[C] = xc;
                const double p[3] = {double(g[0]) - o[0], double(g[1]) - o[1], double(g[2]) - o[2]};
                const vox::Overlap ov = vox::testTriBox(setup, p);
                if (ov == vox::Overlap::No) continue;
                if (ov == vox::Overlap::Ambiguous) {
                  ++exactHere;
                  if (!vox::exactTriBoxOverlap(a, b, c, p)) continue;
                }
                ++touchesHere;
                // Sample the material (alpha test, colour) for this sub-cell.
                float rgb[3] = {1, 1, 1};
                if (plan.defaultColor) {
                  if (plan.alphaTest && plan.factor[3] < plan.cutoff) { ++rejectedHere; continue; }
                  for (int k = 0; k < 3; ++k) rgb[k] = plan.defaultColor[k];
                } else {
                  float alpha = 1;
                  if (plan.texture) {
                    // Sample point: the sub-cell centre projected onto the triangle's plane,
                    // clamped into the triangle.
                    const double q[3] = {p[0] + 0.5 - a[0], p[1] + 0.5 - a[1], p[2] + 0.5 - a[2]};
                    double w[3];
                    bary.weights(q, w);
                    const float u = float(w[0] * tri.uv[0][0] + w[1] * tri.uv[1][0] + w[2] * tri.uv[2][0]);
                    const float v = float(w[0] * tri.uv[0][1] + w[1] * tri.uv[1][1] + w[2] * tri.uv[2][1]);
                    const vox::Footprint fp = vox::footprint(*level, u, v);
                    if (plan.alphaTest) alpha = vox::sampleAlpha(*level, fp);
                    if (plan.alphaTest && alpha * plan.factor[3] < plan.cutoff) { ++rejectedHere; continue; }
                    vox::sampleColor(*level, fp, rgb);
                  } else if (plan.alphaTest && plan.factor[3] < plan.cutoff) {
                    ++rejectedHere;
                    continue;
                  }
                  for (int k = 0; k < 3; ++k)
                    rgb[k] *= plan.factor[k] * (mesh.hasTriangleColors ? tri.color[size_t(k)] : 1.0f);
                }
                const size_t l[3] = {size_t(g[0] - f0[0]), size_t(g[1] - f0[1]), size_t(g[2] - f0[2])};
                const int cell = (cellOf[l[0]] * kTile + cellOf[l[1]]) * kTile + cellOf[l[2]];
                const int bit = (subOf[l[0]] * S + subOf[l[1]]) * S + subOf[l[2]];
                const size_t wi = size_t(cell) * size_t(words) + size_t(bit >> 6);
                s.any[wi] |= uint64_t(1) << (bit & 63);
                if (plan.wood) s.wood[wi] |= uint64_t(1) << (bit & 63);
                for (int k = 0; k < 3; ++k) s.colour[size_t(cell) * 3 + size_t(k)] += rgb[k];
                ++s.touches[size_t(cell)];
                s.used[size_t(cell)] = 1;
              }
            }
        }
      }
      // Average the sub-cells into lattice cells.
      std::vector<LatticeCell>& out = tileCells[ti];
      for (int cell = 0; cell < cellsPerTile; ++cell) {
        if (!s.used[size_t(cell)]) continue;
        int count = 0, woodCount = 0;
        for (int w = 0; w < words; ++w) {
          count += __builtin_popcountll(s.any[size_t(cell) * size_t(words) + size_t(w)]);
          woodCount += __builtin_popcountll(s.wood[size_t(cell) * size_t(words) + size_t(w)]);
        }
        LatticeCell lc;
        lc.i = int32_t(tc[0] * kTile + cell / (kTile * kTile));
        lc.j = int32_t(tc[1] * kTile + (cell / kTile) % kTile);
        lc.k = int32_t(tc[2] * kTile + cell % kTile);
        lc.density = float(count) / float(sub3);
        lc.wood = float(woodCount) / float(count);
        const double n = double(s.touches[size_t(cell)]);
        for (int k = 0; k < 3; ++k) lc.albedo[k] = float(s.colour[size_t(cell) * 3 + size_t(k)] / n);
        out.push_back(lc);
      }
      fineTouches += touchesHere;
      alphaRejected += rejectedHere;
      exactTests += exactHere;
      progress.add(1);
    }
  });
  progress.done();

  size_t total = 0;
  for (auto& v : tileCells) total += v.size();
  result.cells.reserve(total);
  for (auto& v : tileCells) result.cells.insert(result.cells.end(), v.begin(), v.end());
  std::sort(result.cells.begin(), result.cells.end(), [](const LatticeCell& x, const LatticeCell& y) {
    return std::tie(x.i, x.j, x.k) < std::tie(y.i, y.j, y.k);
  });
  st.occupiedCells = result.cells.size();
  st.fineTouches = fineTouches;
  st.alphaRejected = alphaRejected;
  st.exactTests = exactTests;
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
  st.secondsVoxelize = secondsSince(t0);
  return result;
}

}  // namespace canopy
