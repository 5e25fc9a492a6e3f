// scene.cpp: HostScene from a CanopyFile (see scene.h).
#include "runtime/scene.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>

#include "canopy/cli.h"
#include "canopy/errors.h"
#include "formats/scene_json.h"
#include "runtime/affine.h"

namespace canopy::play {
namespace {

Affine toAffine(const M34& m) {
  Affine a;
  for (int i = 0; i < 12; ++i) a.m[i] = float(m[size_t(i)]);
  return a;
}

M34 apply(const M34& m, double x, double y, double z, std::array<double, 3>& out) {
  for (int i = 0; i < 3; ++i) out[size_t(i)] = m[size_t(i * 4)] * x + m[size_t(i * 4 + 1)] * y + m[size_t(i * 4 + 2)] * z + m[size_t(i * 4 + 3)];
  return m;
}

// The cells of the instance grid that instance i's world box overlaps: [c0, c1] on each axis.
void gridRange(const HostScene& s, uint32_t i, int c0[3], int c1[3]) {
  for (int a = 0; a < 3; ++a) {
    c0[a] = std::clamp(int(std::floor((s.instances[i].boundsLo[a] - s.gridLo[a]) / s.gridCell[a])), 0, s.gridDim[a] - 1);
    c1[a] = std::clamp(int(std::floor((s.instances[i].boundsHi[a] - s.gridLo[a]) / s.gridCell[a])), 0, s.gridDim[a] - 1);
  }
}

// Model m's leaves with matter (no child tile; a brick, or a uniform non-zero density), each with
// its level and first lattice cell, from the resident node tiles.
struct Leaf {
  CanopyNode node;
  uint32_t level;
  int64_t cell0[3];
};
std::vector<Leaf> modelLeaves(const CanopyFile& f, uint32_t m) {
  const CanopyModel& M = f.model(m);
  const CanopyNode* tiles = f.tiles(m);
  std::vector<Leaf> leaves, stack{{M.root, 0, {M.octreeOrigin[0], M.octreeOrigin[1], M.octreeOrigin[2]}}};
  while (!stack.empty()) {
    const Leaf n = stack.back();
    stack.pop_back();
    if (n.node.child != kCanopyNone && n.node.child < M.tileCount && n.level < M.depth) {
      const int64_t half = int64_t(M.rootCells >> (n.level + 1));
      for (uint32_t c = 0; c < 8; ++c)
        stack.push_back({tiles[size_t(n.node.child) * 8 + c], n.level + 1,
                         {n.cell0[0] + (c & 1) * half, n.cell0[1] + ((c >> 1) & 1) * half, n.cell0[2] + ((c >> 2) & 1) * half}});
    } else if (n.node.brick != kCanopyNone || n.node.density > 0.0f) {
      leaves.push_back(n);
    }
  }
  return leaves;
}

// The lattice index height of model m's lowest matter: the bottom face (index y - 0.5) of its lowest
// cell of non-zero density; +inf for a model without matter. The leaves are visited bottom first
// until none can lie lower, reading the bricks of the lowest (a few page reads). A brick page that
// cannot be read counts its node's bottom face (never higher than the truth).
double modelBaseIndexY(const CanopyFile& f, uint32_t m, std::vector<Leaf> leaves) {
  const CanopyModel& M = f.model(m);
  std::sort(leaves.begin(), leaves.end(), [](const Leaf& a, const Leaf& b) { return a.cell0[1] < b.cell0[1]; });
  double best = std::numeric_limits<double>::infinity();
  std::vector<unsigned char> page(f.header().pageBytes);
  uint32_t loaded = kCanopyNone;
  for (const Leaf& n : leaves) {
    const double bottom = double(n.cell0[1]) - 0.5;
    if (bottom >= best) break;
    if (n.node.brick == kCanopyNone || n.node.brick >= M.brickCount) {
      best = bottom;
      continue;
    }
    const CanopyFile::BrickLocation at = f.brickLocation(m, n.node.brick);  // dense or (2.0) sparse
    const uint32_t pageIndex = at.page;
    try {
      if (pageIndex != loaded) {
        loaded = kCanopyNone;  // the buffer holds no valid page until the read has passed its checks
        f.readPage(pageIndex, page.data());
        loaded = pageIndex;
      }
    } catch (const std::exception&) {
      best = bottom;
      continue;
    }
    const CanopyBrickView b = canopyBrickInPage(page.data(), at.slot);
    const CanopySparseBrickView sb = at.sparse ? canopySparseBrickInPage(page.data(), at.slot) : CanopySparseBrickView{};
    auto density = [&](uint32_t idx) {
      float d;
      uint32_t mat;
      if (at.sparse) sb.load(idx, d, mat);
      else canopyLoadVoxel(b, idx, d, mat);
      return d;
    };
    const double voxelCells = double(M.rootCells >> n.level) / kCanopyBrickSize;
    for (uint32_t y = 1; y <= kCanopyBrickSize; ++y) {
      bool any = false;
      for (uint32_t z = 1; z <= kCanopyBrickSize && !any; ++z)
        for (uint32_t x = 1; x <= kCanopyBrickSize && !any; ++x) any = density(canopyVoxelIndex(x, y, z)) > 0.0f;
      if (any) {
        best = std::min(best, bottom + double(y - 1) * voxelCells);
        break;
      }
    }
  }
  return best;
}

// The cells [lo, hi) per axis that hold model m's leaves with matter, within its lattice; the whole
// lattice for a model without matter.
void modelMatterBox(const CanopyModel& M, const std::vector<Leaf>& leaves, int64_t lo[3], int64_t hi[3]) {
  for (int a = 0; a < 3; ++a) lo[a] = INT64_MAX, hi[a] = INT64_MIN;
  for (const Leaf& n : leaves)
    for (int a = 0; a < 3; ++a) {
      lo[a] = std::min(lo[a], n.cell0[a]);
      hi[a] = std::max(hi[a], n.cell0[a] + int64_t(M.rootCells >> n.level));
    }
  for (int a = 0; a < 3; ++a) {
    if (leaves.empty()) lo[a] = M.latticeMin[a], hi[a] = int64_t(M.latticeMax[a]) + 1;
    lo[a] = std::max(lo[a], int64_t(M.latticeMin[a]));
    hi[a] = std::min(hi[a], int64_t(M.latticeMax[a]) + 1);
  }
}

// The models' views and the maps each instance's transform is composed with: lattice index ->
// model space (indexToModel) and model space -> octree unit space.
void addModels(const CanopyFile& f, HostScene& s, std::vector<M34>& latticeToModel, std::vector<M34>& modelToUnit) {
  const CanopyFileHeader& h = f.header();
  latticeToModel.resize(f.modelCount());
  modelToUnit.resize(f.modelCount());
  for (uint32_t m = 0; m < f.modelCount(); ++m) {
    const CanopyModel& M = f.model(m);
    ModelView v{};
    v.tiles = f.tiles(m);
    v.tileCount = M.tileCount;
    v.root = M.root;
    v.depth = M.depth;
    v.rootCells = M.rootCells;
    v.firstBrickPage = M.firstBrickPage;
    // The reader has checked the light pages' range and that every brick of levels 0..lightDepth
    // has its item; a model flagged lit may have Haar light too (the light lattice's exact light).
    v.hasLight = (M.flags & kCanopyModelHasLight) && M.lightCount > 0 && h.lightItemsPerPage > 0 ? 1u : 0u;
    v.haarLight = v.hasLight && (M.flags & kCanopyModelHaarLight) ? 1u : 0u;
    v.firstLightPage = M.firstLightPage;
    v.lightDepth = canopyLightDepth(M);
    v.lightRootCells = M.rootCells >> M.detailLevels;
    v.extinctionScale = std::ldexp(1.0f, -int(M.detailLevels));
    for (int a = 0; a < 3; ++a) v.origin[a] = M.octreeOrigin[a] >> M.detailLevels;
    v.denseBricks = M.brickCount - M.sparseBricks;
    v.firstSparsePage = M.firstSparsePage;
    v.sparseIndex = M.sparseBricks > 0 ? f.sparseIndex().data() + M.firstSparseIndex : nullptr;
    if (v.haarLight) v.haar = f.haarView(m);
    if ((M.flags & kCanopyModelHasLight) && !v.hasLight)
      logWarn(f.path() + ": model '" + std::string(M.name, strnlen(M.name, sizeof(M.name))) +
              "' is flagged lit but has no light item per brick; it is lit as density-only (direct sun + ambient)");
    s.litModels += v.hasLight;
    s.detailModels += M.detailLevels > 0 || M.sparseBricks > 0 ? 1u : 0u;
    s.haarModels += v.haarLight ? 1u : 0u;
    if (v.hasLight && !(M.flags & kCanopyModelScatteredSun)) {
      ++s.totalSunModels;
      logWarn(f.path() + ": model '" + std::string(M.name, strnlen(M.name, sizeof(M.name))) +
              "' has sun bases that include the direct beam (packed from canopy-lbsolve --sun-bases total, or from a light "
              "file older than 2026-12): the direct sun is counted twice; re-run canopy-lbsolve and canopy-octreepack");
    }
    s.models.push_back(v);
    s.modelFirstTile.push_back(M.firstTile);
    s.modelFirstHaarIndex.push_back(M.firstHaarIndex);
    s.modelFirstSparseIndex.push_back(M.firstSparseIndex);
    s.brickPageBytes += uint64_t(M.brickPageCount) * h.pageBytes;
    if (v.hasLight) s.lightPageBytes += uint64_t(M.lightPageCount) * h.pageBytes;
    if (v.haarLight) s.haarPageBytes += uint64_t(M.haarPageCount) * h.pageBytes;
    M34 i2m;
    for (int k = 0; k < 12; ++k) i2m[size_t(k)] = M.indexToModel[k];
    latticeToModel[m] = i2m;
    // lattice index p -> unit u = (p - origin + 0.5) / rootCells
    const double inv = 1.0 / double(M.rootCells);
    modelToUnit[m] = compose(M34{inv, 0, 0, (0.5 - M.octreeOrigin[0]) * inv, 0, inv, 0, (0.5 - M.octreeOrigin[1]) * inv, 0, 0,
                                 inv, (0.5 - M.octreeOrigin[2]) * inv},
                             invert(i2m, f.path() + ": model " + std::to_string(m) + " indexToModel"));
  }
}

// The instances' views (transforms, march extents, world boxes), the ground's base, and the world
// bounds of their lattice boxes in lo/hi.
void addInstances(const CanopyFile& f, HostScene& s, const std::vector<M34>& latticeToModel, const std::vector<M34>& modelToUnit,
                  double lo[3], double hi[3]) {
  std::vector<double> baseIndexY(f.modelCount(), 0.0);
  std::vector<std::array<int64_t, 6>> matterBox(f.modelCount());  // cells [lo, hi) per axis
  for (uint32_t m = 0; m < f.modelCount(); ++m) {
    const std::vector<Leaf> leaves = modelLeaves(f, m);
    modelMatterBox(f.model(m), leaves, matterBox[m].data(), matterBox[m].data() + 3);
    baseIndexY[m] = modelBaseIndexY(f, m, leaves);
  }
  for (uint32_t i = 0; i < f.instanceCount(); ++i) {
    const CanopyInstance& I = f.instance(i);
    const CanopyModel& M = f.model(I.model);
    M34 m2w;
    for (int k = 0; k < 12; ++k) m2w[size_t(k)] = I.modelToWorld[k];
    const std::string what = f.path() + ": instance " + std::to_string(i);
    const M34 l2w = compose(m2w, latticeToModel[I.model]);
    const M34 w2l = invert(l2w, what);
    InstanceView v{};
    v.worldToUnit = toAffine(compose(modelToUnit[I.model], invert(m2w, what)));
    v.cellWorld = float(std::cbrt(std::fabs(det3(l2w))));
    v.model = I.model;
    // The instance's extent for the march: the box of its model's leaves with matter (a tree's
    // lattice is a cube around its height; the leaves' box is its crown and trunk, a fraction of
    // that in a forest where neighbours' cubes overlap), in unit space and as a world AABB. Outside
    // it every leaf is empty (density 0), so at the finest level the march only stops evaluating
    // empty nodes there; a coarser level's brick, whose MIP spreads matter up to one of its voxels
    // past the box (a pixel's footprint or less, by the level rule), is cut at the box, and so is
    // the shadow map's node-mean extinction (the image moved by 0.11-0.29 % of the covered mean on
    // the real forest). The scene's bounds (framing, shadow map, grid extent) stay the lattices'.
    const int64_t* box = matterBox[I.model].data();
    float latLo[3], latHi[3];
    for (int a = 0; a < 3; ++a) {
      v.unitLo[a] = float(double(box[a] - M.octreeOrigin[a]) / M.rootCells);
      v.unitHi[a] = float(double(box[3 + a] - M.octreeOrigin[a]) / M.rootCells);
      v.boundsLo[a] = latLo[a] = 3e38f;
      v.boundsHi[a] = latHi[a] = -3e38f;
    }
    for (int c = 0; c < 8; ++c) {  // the boxes' corners (cells centred at integers)
      std::array<double, 3> p, q;
      apply(l2w, (c & 1) ? M.latticeMax[0] + 0.5 : M.latticeMin[0] - 0.5, (c & 2) ? M.latticeMax[1] + 0.5 : M.latticeMin[1] - 0.5,
            (c & 4) ? M.latticeMax[2] + 0.5 : M.latticeMin[2] - 0.5, p);
      apply(l2w, double((c & 1) ? box[3] : box[0]) - 0.5, double((c & 2) ? box[4] : box[1]) - 0.5, double((c & 4) ? box[5] : box[2]) - 0.5, q);
      for (int a = 0; a < 3; ++a) {
        latLo[a] = std::min(latLo[a], float(p[size_t(a)]));
        latHi[a] = std::max(latHi[a], float(p[size_t(a)]));
        v.boundsLo[a] = std::min(v.boundsLo[a], float(q[size_t(a)]));
        v.boundsHi[a] = std::max(v.boundsHi[a], float(q[size_t(a)]));
      }
    }
    for (int a = 0; a < 3; ++a) {
      // (a NaN ray position from farther crashed the descent)
      if (!(std::fabs(latLo[a]) <= kMaxWorldCoordinate && std::fabs(latHi[a]) <= kMaxWorldCoordinate))
        throw invalidInput(what + ": its world bounds reach beyond +-1e9 m (too far for single-precision rendering)");
      lo[a] = std::min(lo[a], double(latLo[a]));
      hi[a] = std::max(hi[a], double(latHi[a]));
    }
    if (std::isfinite(baseIndexY[I.model])) {  // the instance's base: its model's lowest matter, below the lattice's centre
      std::array<double, 3> p;
      apply(l2w, 0.5 * (M.latticeMin[0] + M.latticeMax[0]), baseIndexY[I.model], 0.5 * (M.latticeMin[2] + M.latticeMax[2]), p);
      s.groundBase = std::min(s.groundBase, float(p[1]));
    }
    s.instances.push_back(v);
    Affine lin = toAffine(w2l);
    lin.m[3] = lin.m[7] = lin.m[11] = 0.0f;
    s.worldToLatticeLinear.push_back(lin);
  }
}

// The uniform grid of instance boxes over the scene's bounds lo/hi (SceneView::grid*).
void buildInstanceGrid(HostScene& s, const double lo[3], const double hi[3]) {
  s.empty = s.instances.empty();
  if (!s.empty) {
    // Uniform grid: about one instance per cell, at most 64 cells per axis.
    const double n = double(s.instances.size());
    double ext[3];
    for (int a = 0; a < 3; ++a) {
      ext[a] = std::max(hi[a] - lo[a], 1e-6);
      s.boundsLo[a] = float(lo[a]);
      s.boundsHi[a] = float(hi[a]);
    }
    const double cell = std::cbrt(ext[0] * ext[1] * ext[2] / n);
    for (int a = 0; a < 3; ++a) {
      s.gridDim[a] = int(std::clamp(std::ceil(ext[a] / std::max(cell, 1e-9)), 1.0, 64.0));
      // a small margin so that rounding never leaves a box outside the grid
      const double pad = ext[a] * 1e-4;
      s.gridLo[a] = float(lo[a] - pad);
      s.gridCell[a] = float((ext[a] + 2 * pad) / s.gridDim[a]);
    }
    const size_t cells = size_t(s.gridDim[0]) * s.gridDim[1] * s.gridDim[2];
    // Each cell's instances (gridStart/gridItems) and, per entry face, those a walk meets first
    // when it enters the cell through that face (gridFaceStart/gridFaceItems, cone.h walkAddCell):
    // the instances whose cell range starts there along the walk's direction, i.e. that the cell
    // behind the face does not list (an instance's cells are a box of cells). Lists in CSR form,
    // instances ascending in each: counted in a first pass over every (cell, instance) pair,
    // filled in a second.
    s.gridStart.assign(cells + 1, 0);
    s.gridFaceStart.assign(cells * 6 + 1, 0);
    std::vector<uint32_t> cellAt, faceAt;
    for (int pass = 0; pass < 2; ++pass) {
      for (uint32_t i = 0; i < s.instances.size(); ++i) {
        int c0[3], c1[3];
        gridRange(s, i, c0, c1);
        for (int z = c0[2]; z <= c1[2]; ++z)
          for (int y = c0[1]; y <= c1[1]; ++y)
            for (int x = c0[0]; x <= c1[0]; ++x) {
              const int at[3] = {x, y, z};
              const size_t c = size_t(x + s.gridDim[0] * (y + s.gridDim[1] * z));
              if (pass == 0) ++s.gridStart[c + 1];
              else s.gridItems[cellAt[c]++] = i;
              for (int a = 0; a < 3; ++a)
                for (int side = 0; side < 2; ++side) {  // side 0: entered moving +a (range starts here), 1: moving -a
                  if (at[a] != (side == 0 ? c0[a] : c1[a])) continue;
                  const size_t k = c * 6 + size_t(2 * a + side);
                  if (pass == 0) ++s.gridFaceStart[k + 1];
                  else s.gridFaceItems[faceAt[k]++] = i;
                }
            }
      }
      if (pass == 0) {
        for (size_t c = 0; c < cells; ++c) s.gridStart[c + 1] += s.gridStart[c];
        for (size_t k = 0; k < cells * 6; ++k) s.gridFaceStart[k + 1] += s.gridFaceStart[k];
        s.gridItems.resize(s.gridStart[cells]);
        s.gridFaceItems.resize(s.gridFaceStart[cells * 6]);
        cellAt.assign(s.gridStart.begin(), s.gridStart.end() - 1);
        faceAt.assign(s.gridFaceStart.begin(), s.gridFaceStart.end() - 1);
      }
    }
  } else {
    s.gridStart.assign(2, 0);
    s.gridFaceStart.assign(7, 0);
  }
}

// The coarse scene lattice (lbsolve --scene) of the file, if it has one.
void addSceneLight(const CanopyFile& f, HostScene& s) {
  if (!f.hasSceneLight()) return;
  const CanopySceneLight& L = f.sceneLight();
  // sceneLightFactors indexes the lattice's nodes in 32 bits (cone_light.h); the file's reader allows
  // up to 65536 nodes a side (such a lattice's section alone would be 16 GiB or more)
  if (uint64_t(L.dim[0]) * uint64_t(L.dim[1]) * uint64_t(L.dim[2]) > uint64_t(UINT32_MAX))
    throw invalidInput(f.path() + ": scene light lattice of " + std::to_string(L.dim[0]) + "x" + std::to_string(L.dim[1]) + "x" +
                       std::to_string(L.dim[2]) + " nodes: more than the player's 2^32 - 1");
  M34 i2w;
  for (int k = 0; k < 12; ++k) i2w[size_t(k)] = L.indexToWorld[k];
  s.hasSceneLight = true;
  s.lightBases = f.sceneLightBases();
  s.lightBaseValues = f.sceneLightValues();
  const M34 w2i = invert(i2w, f.path() + ": scene light indexToWorld");
  s.light.worldToIndex = toAffine(w2i);
  s.worldToSceneLinear = toAffine(w2i);
  s.worldToSceneLinear.m[3] = s.worldToSceneLinear.m[7] = s.worldToSceneLinear.m[11] = 0.0f;
  for (int a = 0; a < 3; ++a) {
    s.light.min[a] = L.min[a];
    s.light.dim[a] = L.dim[a];
  }
  // B00 alone: one factor for both terms, built once. With the sun bases: B00 and no sun (until setSun).
  s.lightSun = sun::Weights();
  buildSceneLightPairs(s.lightBaseValues, s.lightBases, size_t(L.dim[0]) * size_t(L.dim[1]) * size_t(L.dim[2]), s.lightSun, s.lightPairs);
  ++s.lightVersion;
}

}  // namespace

// Each model's descent table (ModelView::levelNodes): level by level, a cell's node is its parent
// cell's child where the parent cell's node sits at the parent level and has children (the step a
// descent takes), else the parent cell's node (a leaf ends the descent there).
void addDescentTables(HostScene& s) {
  const uint32_t lightItemsPerPage = s.lightItemsPerPage;
  s.levelNodes.clear(), s.levelOf.clear(), s.lightBricks.clear(), s.modelFirstLevelNode.clear();
  for (ModelView& m : s.models) {
    const uint32_t levels = std::min(m.depth + 1, kDescentTableLevels);
    const size_t first = s.levelNodes.size();
    s.modelFirstLevelNode.push_back(uint32_t(first));
    size_t count = 0;
    for (uint32_t L = 0; L < levels; ++L) count += size_t(1) << (3 * L);
    s.levelNodes.resize(first + count);
    s.levelOf.resize(first + count);
    s.lightBricks.resize(first + count);
    s.levelNodes[first] = m.root;
    s.levelOf[first] = 0;
    s.lightBricks[first] = m.root.brick;  // level 0 <= lightDepth
    size_t parentAt = first, at = first + 1;
    for (uint32_t L = 1; L < levels; ++L) {
      const uint32_t n = 1u << L, pn = n >> 1;
      for (uint32_t z = 0; z < n; ++z)
        for (uint32_t y = 0; y < n; ++y)
          for (uint32_t x = 0; x < n; ++x) {
            const size_t p = parentAt + (x >> 1) + pn * ((y >> 1) + pn * size_t(z >> 1));
            const CanopyNode& parent = s.levelNodes[p];
            const bool steps = (s.levelOf[p] & 15u) == L - 1 && parent.child != kCanopyNone && parent.child < m.tileCount;
            const size_t e = at + x + n * (y + n * size_t(z));
            s.levelNodes[e] = steps ? m.tiles[size_t(parent.child) * 8 + ((x & 1) | (y & 1) << 1 | (z & 1) << 2)] : parent;
            s.levelOf[e] = s.levelOf[p];
            s.lightBricks[e] = s.lightBricks[p];
            if (steps) {
              s.levelOf[e] = uint8_t((s.levelOf[p] & 0xF0u) | L);
              if (s.levelNodes[e].brick != kCanopyNone && L <= m.lightDepth) {
                s.levelOf[e] = uint8_t(L << 4 | L);
                s.lightBricks[e] = s.levelNodes[e].brick;
              }
            }
          }
      parentAt = at;
      at += size_t(n) * n * n;
    }
    m.tableLevels = levels;
    m.rootLightPage = m.hasLight && m.root.brick != kCanopyNone ? m.firstLightPage + m.root.brick / lightItemsPerPage : kCanopyNone;
  }
  for (size_t i = 0; i < s.models.size(); ++i) {
    s.models[i].levelNodes = s.levelNodes.data() + s.modelFirstLevelNode[i];
    s.models[i].levelOf = s.levelOf.data() + s.modelFirstLevelNode[i];
    s.models[i].lightBricks = s.lightBricks.data() + s.modelFirstLevelNode[i];
  }
}

HostScene buildScene(const CanopyFile& f) {
  HostScene s;
  const CanopyFileHeader& h = f.header();
  s.pageCount = h.pageCount;
  s.pageBytes = h.pageBytes;
  s.bricksPerPage = h.bricksPerPage;
  s.lightItemsPerPage = h.lightItemsPerPage;
  s.haarIndex = &f.haarIndex();
  s.sparseIndex = &f.sparseIndex();
  std::vector<M34> latticeToModel, modelToUnit;
  addModels(f, s, latticeToModel, modelToUnit);
  double lo[3] = {1e300, 1e300, 1e300}, hi[3] = {-1e300, -1e300, -1e300};
  addInstances(f, s, latticeToModel, modelToUnit, lo, hi);
  buildInstanceGrid(s, lo, hi);
  addSceneLight(f, s);
  s.far = planFarField(s);
  return s;
}

void buildSceneLightPairs(const std::vector<float>& values, uint32_t bases, size_t nodes, const sun::Weights& w,
                          std::vector<SceneLightPair>& out) {
  if ((bases != 1 && bases != 1 + kCanopySceneSunBases) || values.size() != nodes * bases)
    throw invalidInput("scene light: " + std::to_string(values.size()) + " values are not " + std::to_string(bases) + " bases of " +
                       std::to_string(nodes) + " nodes");
  out.resize(nodes);
  for (size_t i = 0; i < nodes; ++i) out[i].ambient = values[i];
  if (bases == 1) {
    for (size_t i = 0; i < nodes; ++i) out[i].sun = values[i];
    return;
  }
  for (size_t i = 0; i < nodes; ++i) out[i].sun = 0.0f;
  for (int v = 0; v < 3; ++v) {
    if (!(w.weight[v] != 0.0f) || w.base[v] < 1 || w.base[v] > int(kCanopySceneSunBases)) continue;
    const float* b = values.data() + size_t(w.base[v]) * nodes;
    for (size_t i = 0; i < nodes; ++i) out[i].sun += w.weight[v] * b[i];
  }
}

void HostScene::setSun(V3 toSun) {
  for (size_t i = 0; i < instances.size(); ++i) {
    // The lookup wants the direction the light TRAVELS (-toSun) in the LB lattice's index axes:
    // the inverse of the instance's linear part (lattice -> model -> world) applied to it, i.e. the
    // inverse rotation (and scale) of the instance, normalised. For a rotation + uniform scale this
    // is the transpose of the rotation; a non-uniform scale maps directions as displacements.
    const V3 d = normalize(applyVector(worldToLatticeLinear[i], toSun * -1.0f));
    sun::lookup(d.x, d.y, d.z, instances[i].sunWeights);
  }
  // The scene lattice's sun factor (§4.3: the coarse level relit with the same lookup), in its own
  // index axes (world axes scaled by its cell); rebuilt only when the lookup changes.
  if (hasSceneLight && lightBases > 1) {
    const V3 d = normalize(applyVector(worldToSceneLinear, toSun * -1.0f));
    sun::Weights w;
    sun::lookup(d.x, d.y, d.z, w);
    bool same = w.face == lightSun.face;
    for (int v = 0; v < 3; ++v) same = same && w.base[v] == lightSun.base[v] && w.weight[v] == lightSun.weight[v];
    if (!same) {
      lightSun = w;
      buildSceneLightPairs(lightBaseValues, lightBases, lightPairs.size(), lightSun, lightPairs);
      ++lightVersion;
    }
  }
}

namespace {

// The voxel edge h0 grown until (ceil(extent / h) + 3) per axis fits in maxVoxels; dims out.
double fitVoxel(const double extent[3], double h, uint32_t maxVoxels, int32_t dim[3]) {
  const double cap = std::max(double(maxVoxels), 27.0);
  for (;;) {
    double n = 1.0;
    for (int a = 0; a < 3; ++a) {
      dim[a] = int32_t(std::ceil(extent[a] / h)) + 3;
      n *= double(dim[a]);
    }
    if (n <= cap) return h;
    h *= std::max(std::cbrt(n / cap), 1.0001);
  }
}

}  // namespace

ExtinctionGridView planExtinctionGrid(const HostScene& s, const ShadeParams& shade) {
  ExtinctionGridView g{};
  g.dim[0] = g.dim[1] = g.dim[2] = 1;
  g.voxel = 1.0f;
  if (s.empty) return g;
  float cell = 3e38f;
  for (const InstanceView& i : s.instances) cell = std::min(cell, i.cellWorld);
  double extent[3];
  for (int a = 0; a < 3; ++a) extent[a] = double(s.boundsHi[a]) - s.boundsLo[a];
  const double h = fitVoxel(extent, std::max(double(shade.shadowMapCells) * cell, 1e-6), shade.shadowMapMaxVoxels, g.dim);
  g.voxel = float(h);
  for (int a = 0; a < 3; ++a) g.lo[a] = float(s.boundsLo[a] - h);  // voxel 1's centre at the low corner
  return g;
}

FarFieldView planFarField(const HostScene& s) {
  FarFieldView g{};
  g.dim[0] = g.dim[1] = g.dim[2] = 1;
  g.voxel = 1.0f;
  if (s.empty) return g;
  double voxel = 0.0;
  for (const InstanceView& i : s.instances) {
    // the coarsest level's voxel (rootCells / 8 cells), or the finest node where that is wider (the
    // grid is built from node means: node tiles are resident, bricks may not be)
    const ModelView& m = s.models[i.model];
    voxel = std::max(voxel, std::max(double(m.rootCells) / 8.0, double(m.rootCells >> m.depth)) * double(i.cellWorld));
  }
  double extent[3];
  for (int a = 0; a < 3; ++a) extent[a] = double(s.boundsHi[a]) - s.boundsLo[a];
  const double h = fitVoxel(extent, std::max(voxel, 1e-6), kFarFieldMaxVoxels, g.dim);
  g.voxel = float(h);
  for (int a = 0; a < 3; ++a) g.lo[a] = float(s.boundsLo[a] - h);  // voxel 1's centre at the low corner
  return g;
}

bool farFieldReachable(const HostScene& s, const ShadeParams& shade, const CameraView& camera) {
  if (s.empty || shade.farStart < 0.0f) return false;
  // the nearest start of any pixel's cone: the largest footprint per unit t is the pixel angle
  // (off-axis pixels subtend less, cameraRay)
  const double start = shade.farStart > 0.0f ? double(shade.farStart) : double(s.far.voxel) / double(camera.pixelAngle);
  double far2 = 0.0;  // the farthest corner of the scene's bounds from the eye
  for (int c = 0; c < 8; ++c) {
    const double d[3] = {double((c & 1) ? s.boundsHi[0] : s.boundsLo[0]) - camera.position.x,
                         double((c & 2) ? s.boundsHi[1] : s.boundsLo[1]) - camera.position.y,
                         double((c & 4) ? s.boundsHi[2] : s.boundsLo[2]) - camera.position.z};
    far2 = std::max(far2, d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
  }
  return std::sqrt(far2) > 0.99 * start;  // a margin for stereo's second eye, which uses the first eye's far field
}

ShadowMapView planShadowMap(const HostScene& s, const ShadeParams& shade, const ExtinctionGridView& grid, int& sub) {
  ShadowMapView m{};
  m.dim[0] = m.dim[1] = m.dim[2] = 1;
  m.voxel = 1.0f;
  sub = 1;
  if (s.empty) return m;
  const V3 w = normalize(shade.toSun * -1.0f);
  const V3 helper = std::fabs(w.x) > 0.9f ? v3(0, 0, 1) : v3(1, 0, 0);
  const V3 u = normalize(cross(helper, w));
  m.axis[0] = u;
  m.axis[1] = cross(w, u);
  m.axis[2] = w;
  double lo[3] = {1e300, 1e300, 1e300}, hi[3] = {-1e300, -1e300, -1e300};
  for (int c = 0; c < 8; ++c) {
    const V3 p = v3((c & 1) ? s.boundsHi[0] : s.boundsLo[0], (c & 2) ? s.boundsHi[1] : s.boundsLo[1], (c & 4) ? s.boundsHi[2] : s.boundsLo[2]);
    for (int a = 0; a < 3; ++a) {
      lo[a] = std::min(lo[a], double(dot(p, m.axis[a])));
      hi[a] = std::max(hi[a], double(dot(p, m.axis[a])));
    }
  }
  const double extent[3] = {hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]};
  const double h = fitVoxel(extent, double(grid.voxel), shade.shadowMapMaxVoxels, m.dim);
  m.voxel = float(h);
  sub = std::max(1, int(std::ceil(h / double(grid.voxel) - 1e-6)));
  // the map's blur: a node (2 extinction voxels, sceneMeanExtinctionAt) or a map voxel, whichever is larger
  m.bias = float(double(shade.shadowMapBias) * std::max(h, 2.0 * double(grid.voxel)));
  // voxel 1's centre at the box's low corner: voxel 0 lies wholly outside it
  m.origin = m.axis[0] * float(lo[0] - h) + m.axis[1] * float(lo[1] - h) + m.axis[2] * float(lo[2] - h);
  return m;
}

SceneView hostSceneView(const HostScene& s) {
  SceneView v{};
  v.models = s.models.data();
  v.instances = s.instances.data();
  v.instanceCount = uint32_t(s.instances.size());
  v.gridStart = s.gridStart.data();
  v.gridItems = s.gridItems.data();
  v.gridFaceStart = s.gridFaceStart.data();
  v.gridFaceItems = s.gridFaceItems.data();
  for (int a = 0; a < 3; ++a) {
    v.gridDim[a] = s.gridDim[a];
    v.gridLo[a] = s.gridLo[a];
    v.gridCell[a] = s.gridCell[a];
  }
  v.pageBytes = s.pageBytes;
  v.bricksPerPage = indexDivisor(s.bricksPerPage);
  v.brickMaskOffset = canopyBrickMaskOffset(s.pageBytes, s.bricksPerPage);
  v.lightItemsPerPage = indexDivisor(s.lightItemsPerPage > 0 ? s.lightItemsPerPage : 1);
  v.litModels = s.litModels;
  v.detailModels = s.detailModels;
  v.haarModels = s.haarModels;
  v.light = s.light;
  v.light.values = s.hasSceneLight ? s.lightPairs.data() : nullptr;
  return v;
}

}  // namespace canopy::play
