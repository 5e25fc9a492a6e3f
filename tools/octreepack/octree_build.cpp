// octree_build.cpp: see octree_build.h.
#include "tools/octreepack/octree_build.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <unordered_map>

#include "canopy/errors.h"
#include "canopy/parallel.h"

namespace canopy::octreepack {
namespace {

constexpr int kB = int(kCanopyBrickSize);  // 8
constexpr int kBlockVoxels = kB * kB * kB;  // 512

// A level's 8^3 block of voxels (one node's interior).
struct Block {
  float d[kBlockVoxels];
  uint32_t m[kBlockVoxels];
  bool constant = false;
};

inline uint64_t packKey(uint32_t x, uint32_t y, uint32_t z) {
  return uint64_t(x) | uint64_t(y) << 20 | uint64_t(z) << 40;
}
inline void unpackKey(uint64_t k, uint32_t b[3]) {
  b[0] = uint32_t(k & 0xFFFFF);
  b[1] = uint32_t((k >> 20) & 0xFFFFF);
  b[2] = uint32_t(k >> 40);
}
inline int localIndex(int x, int y, int z) { return x + kB * (y + kB * z); }

// One level: blocks in ascending key order and a key -> block lookup.
struct Level {
  std::vector<uint64_t> keys;
  std::vector<Block> blocks;
  std::unordered_map<uint64_t, uint32_t> index;
  const Block* find(uint64_t k) const {
    auto it = index.find(k);
    return it == index.end() ? nullptr : &blocks[it->second];
  }
  void buildIndex() {
    index.reserve(keys.size() * 2);
    for (uint32_t i = 0; i < keys.size(); ++i) index.emplace(keys[i], i);
  }
};

bool uniform(const Block& b) {
  for (int i = 1; i < kBlockVoxels; ++i)
    if (b.d[i] != b.d[0] || b.m[i] != b.m[0]) return false;
  return true;
}

// Density-weighted mean of a block's voxels (a brick node's summary value).
void blockMean(const Block& b, float& density, uint32_t& material) {
  double sd = 0, sa[3] = {0, 0, 0}, sw = 0;
  for (int i = 0; i < kBlockVoxels; ++i) {
    const CanopySample s = canopyUnpack(b.d[i], b.m[i]);
    sd += s.density;
    for (int c = 0; c < 3; ++c) sa[c] += double(s.density) * s.albedo[c];
    sw += double(s.density) * s.wood;
  }
  density = float(sd / kBlockVoxels);
  material = sd > 0 ? canopyPackMaterial(float(sa[0] / sd), float(sa[1] / sd), float(sa[2] / sd), float(sw / sd)) : 0u;
}

void checkSource(const ModelSource& src, const std::string& what) {
  int64_t maxDim = 0;
  for (int a = 0; a < 3; ++a) {
    if (src.latticeMax[a] < src.latticeMin[a]) throw invalidInput(what + ": empty lattice (max < min)");
    maxDim = std::max<int64_t>(maxDim, int64_t(src.latticeMax[a]) - src.latticeMin[a] + 1);
  }
  if (maxDim > (int64_t(kCanopyBrickSize) << kCanopyMaxDepth))
    throw invalidInput(what + ": lattice edge of " + std::to_string(maxDim) + " cells exceeds the format's " +
                       std::to_string(kCanopyBrickSize << kCanopyMaxDepth));
  for (double v : src.indexToModel)
    if (!std::isfinite(v)) throw invalidInput(what + ": transform is not finite");
  if (src.detailLevels > 4) throw invalidInput(what + ": detail factor 2^" + std::to_string(src.detailLevels) + " exceeds 16");
  const int32_t cellMask = (1 << src.detailLevels) - 1;
  for (int a = 0; a < 3; ++a)
    if (((src.latticeMin[a] | (src.latticeMax[a] + 1)) & cellMask) != 0)
      throw invalidInput(what + ": the detail lattice's bounds are not whole light cells");
  if (src.cells.empty()) throw invalidInput(what + ": density grid has no occupied cells (empty model)");
  for (const SourceCell& c : src.cells) {
    for (int a = 0; a < 3; ++a)
      if (c.ijk[a] < src.latticeMin[a] || c.ijk[a] > src.latticeMax[a])
        throw invalidInput(what + ": occupied cell (" + std::to_string(c.ijk[0]) + "," + std::to_string(c.ijk[1]) + "," +
                           std::to_string(c.ijk[2]) + ") lies outside the lattice bounds");
    if (!std::isfinite(c.density) || c.density < 0 || !std::isfinite(c.wood) || !std::isfinite(c.albedo[0]) ||
        !std::isfinite(c.albedo[1]) || !std::isfinite(c.albedo[2]))
      throw invalidInput(what + ": non-finite or negative value at cell (" + std::to_string(c.ijk[0]) + "," +
                         std::to_string(c.ijk[1]) + "," + std::to_string(c.ijk[2]) + ")");
  }
}

// Finest level from the source cells (sorted: deterministic whatever the input order).
Level finestLevel(const ModelSource& src, const std::string& what) {
  struct Item {
    uint64_t key;
    int local;
    const SourceCell* cell;
  };
  std::vector<Item> items;
  items.reserve(src.cells.size());
  for (const SourceCell& c : src.cells) {
    if (c.density == 0.0f) continue;
    uint32_t r[3];
    for (int a = 0; a < 3; ++a) r[a] = uint32_t(c.ijk[a] - src.latticeMin[a]);
    items.push_back({packKey(r[0] / kB, r[1] / kB, r[2] / kB), localIndex(r[0] % kB, r[1] % kB, r[2] % kB), &c});
  }
  if (items.empty()) throw invalidInput(what + ": density grid has no occupied cells (empty model)");
  std::sort(items.begin(), items.end(),
            [](const Item& a, const Item& b) { return a.key != b.key ? a.key < b.key : a.local < b.local; });
  Level L;
  for (size_t i = 0; i < items.size(); ++i) {
    const Item& it = items[i];
    if (i > 0 && items[i - 1].key == it.key && items[i - 1].local == it.local)
      throw invalidInput(what + ": duplicate occupied cell (" + std::to_string(it.cell->ijk[0]) + "," +
                         std::to_string(it.cell->ijk[1]) + "," + std::to_string(it.cell->ijk[2]) + ")");
    if (L.keys.empty() || L.keys.back() != it.key) {
      L.keys.push_back(it.key);
      L.blocks.emplace_back();
      Block& b = L.blocks.back();
      std::memset(b.d, 0, sizeof b.d);
      std::memset(b.m, 0, sizeof b.m);
    }
    Block& b = L.blocks.back();
    const SourceCell& c = *it.cell;
    b.d[it.local] = c.density;
    b.m[it.local] = canopyPackMaterial(c.albedo[0], c.albedo[1], c.albedo[2], c.wood);
  }
  for (Block& b : L.blocks) b.constant = uniform(b);
  L.buildIndex();
  return L;
}

// Level above `child`: the 2x2x2 box filter (see the header comment for the exact arithmetic).
Level coarserLevel(const Level& child) {
  Level P;
  for (uint64_t k : child.keys) {
    uint32_t b[3];
    unpackKey(k, b);
    P.keys.push_back(packKey(b[0] >> 1, b[1] >> 1, b[2] >> 1));
  }
  std::sort(P.keys.begin(), P.keys.end());
  P.keys.erase(std::unique(P.keys.begin(), P.keys.end()), P.keys.end());
  P.blocks.resize(P.keys.size());
  parallelFor(int64_t(P.keys.size()), [&](int64_t pi) {
    uint32_t pb[3];
    unpackKey(P.keys[size_t(pi)], pb);
    const Block* kids[8];
    for (int c = 0; c < 8; ++c)
      kids[c] = child.find(packKey(2 * pb[0] + (c & 1), 2 * pb[1] + ((c >> 1) & 1), 2 * pb[2] + ((c >> 2) & 1)));
    Block& out = P.blocks[size_t(pi)];
    for (int z = 0; z < kB; ++z)
      for (int y = 0; y < kB; ++y)
        for (int x = 0; x < kB; ++x) {
          const Block* kb = kids[(x >> 2) | ((y >> 2) << 1) | ((z >> 2) << 2)];
          double sd = 0, sa[3] = {0, 0, 0}, sw = 0;
          if (kb) {
            for (int s = 0; s < 8; ++s) {
              const int li = localIndex((2 * x + (s & 1)) & 7, (2 * y + ((s >> 1) & 1)) & 7, (2 * z + ((s >> 2) & 1)) & 7);
              const CanopySample v = canopyUnpack(kb->d[li], kb->m[li]);
              sd += v.density;
              for (int c = 0; c < 3; ++c) sa[c] += double(v.density) * v.albedo[c];
              sw += double(v.density) * v.wood;
            }
          }
          const int li = localIndex(x, y, z);
          out.d[li] = float(sd / 8.0);
          out.m[li] = sd > 0 ? canopyPackMaterial(float(sa[0] / sd), float(sa[1] / sd), float(sa[2] / sd), float(sw / sd)) : 0u;
        }
    bool constant = true;
    for (int c = 0; c < 8 && constant; ++c)
      constant = kids[c] && kids[c]->constant && kids[c]->d[0] == kids[0]->d[0] && kids[c]->m[0] == kids[0]->m[0];
    out.constant = constant && uniform(out);
  });
  P.buildIndex();
  return P;
}

// Light grid of one block (kCanopyLightSize^3 voxels, each 2 block voxels wide), 57 planes.
constexpr int kL = int(kCanopyLightSize);  // 4
constexpr int kLV = kL * kL * kL;           // 64
constexpr int kCh = int(kCanopyLightChannels);
struct LightBlock {
  float v[kCh][kLV];
  bool avail[kLV];
};
inline int lightIndex(int x, int y, int z) { return x + kL * (y + kL * z); }

// Fills unavailable voxels (no occupied block below them) with the mean of the available ones.
void fillUnavailable(LightBlock& b) {
  int n = 0;
  double mean[kCh] = {};
  for (int i = 0; i < kLV; ++i)
    if (b.avail[i]) {
      ++n;
      for (int c = 0; c < kCh; ++c) mean[c] += b.v[c][i];
    }
  for (int i = 0; i < kLV; ++i)
    if (!b.avail[i])
      for (int c = 0; c < kCh; ++c) b.v[c][i] = n ? float(mean[c] / n) : 0.0f;
}

// The finest light level: the mean of the source over each light voxel's 2x2x2 light lattice cells.
void finestLight(const ModelSource& src, const std::string& what, const LightFn& light, const Level& level,
                 std::vector<LightBlock>& lights) {
  int32_t lightMin[3];  // the light lattice's first cell
  for (int a = 0; a < 3; ++a) lightMin[a] = src.latticeMin[a] >> src.detailLevels;
  lights.resize(level.keys.size());
  parallelFor(int64_t(level.keys.size()), [&](int64_t bi) {
    uint32_t k[3];
    unpackKey(level.keys[size_t(bi)], k);
    LightBlock& lb = lights[size_t(bi)];
    float tmp[kCh];
    for (int z = 0; z < kL; ++z)
      for (int y = 0; y < kL; ++y)
        for (int x = 0; x < kL; ++x) {
          double sum[kCh] = {};
          for (int s = 0; s < 8; ++s) {
            const int32_t i = lightMin[0] + int32_t(kB * k[0]) + 2 * x + (s & 1);
            const int32_t j = lightMin[1] + int32_t(kB * k[1]) + 2 * y + ((s >> 1) & 1);
            const int32_t kk = lightMin[2] + int32_t(kB * k[2]) + 2 * z + (s >> 2);
            light(i, j, kk, tmp);
            for (int c = 0; c < kCh; ++c) {
              if (!std::isfinite(tmp[c]))
                throw invalidInput(what + ": lighting is not finite at cell (" + std::to_string(i) + "," + std::to_string(j) + "," +
                                   std::to_string(kk) + ")");
              sum[c] += tmp[c];
            }
          }
          const int li = lightIndex(x, y, z);
          for (int c = 0; c < kCh; ++c) lb.v[c][li] = float(sum[c] / 8.0);
          lb.avail[li] = true;
        }
  });
}

// A coarser light level (L, child level C): the mean of the available 2x2x2 voxels below.
void coarserLight(const Level& L, const Level& C, const std::vector<LightBlock>& below, std::vector<LightBlock>& lights) {
  lights.resize(L.keys.size());
  parallelFor(int64_t(L.keys.size()), [&](int64_t bi) {
    uint32_t k[3];
    unpackKey(L.keys[size_t(bi)], k);
    LightBlock& lb = lights[size_t(bi)];
    for (int z = 0; z < kL; ++z)
      for (int y = 0; y < kL; ++y)
        for (int x = 0; x < kL; ++x) {
          const int li = lightIndex(x, y, z);
          const auto it = C.index.find(packKey(2 * k[0] + uint32_t(x >> 1), 2 * k[1] + uint32_t(y >> 1), 2 * k[2] + uint32_t(z >> 1)));
          lb.avail[li] = false;
          if (it == C.index.end()) continue;
          const LightBlock& cb = below[it->second];
          double sum[kCh] = {};
          int n = 0;
          for (int s = 0; s < 8; ++s) {
            const int ci = lightIndex((2 * x + (s & 1)) & 3, (2 * y + ((s >> 1) & 1)) & 3, (2 * z + (s >> 2)) & 3);
            if (!cb.avail[ci]) continue;
            ++n;
            for (int c = 0; c < kCh; ++c) sum[c] += cb.v[c][ci];
          }
          if (n == 0) continue;
          for (int c = 0; c < kCh; ++c) lb.v[c][li] = float(sum[c] / n);
          lb.avail[li] = true;
        }
  });
}

// Items: interior + border (neighbour block of the same level, else the edge voxel repeated).
// The fill of unavailable voxels happens on copies so that avail flags above stay exact.
void lightItems(const std::vector<Level>& levels, const std::vector<std::vector<LightBlock>>& lights,
                const std::vector<std::pair<uint32_t, uint64_t>>& bricks, std::vector<uint32_t>& out) {
  constexpr size_t kItemWords = kCanopyLightItemBytes / 4;
  out.assign(bricks.size() * kItemWords, 0);
  parallelFor(int64_t(bricks.size()), [&](int64_t bi) {
    const uint32_t level = bricks[size_t(bi)].first;
    const uint64_t key = bricks[size_t(bi)].second;
    const Level& L = levels[level];
    uint32_t k[3];
    unpackKey(key, k);
    const int64_t blocksPerAxis = int64_t(1) << level;
    std::vector<LightBlock> nb(27);  // ~400 KB: on the heap, not a worker thread's stack
    bool has[27];
    for (int i = 0; i < 27; ++i) {
      const int64_t x = int64_t(k[0]) + i % 3 - 1, y = int64_t(k[1]) + (i / 3) % 3 - 1, z = int64_t(k[2]) + i / 9 - 1;
      const bool inside = x >= 0 && y >= 0 && z >= 0 && x < blocksPerAxis && y < blocksPerAxis && z < blocksPerAxis;
      has[i] = false;
      if (!inside) continue;
      auto it = L.index.find(packKey(uint32_t(x), uint32_t(y), uint32_t(z)));
      if (it == L.index.end()) continue;
      has[i] = true;
      nb[i] = lights[level][it->second];
      fillUnavailable(nb[i]);
    }
    uint32_t* item = out.data() + size_t(bi) * kItemWords;
    for (int z = 0; z < int(kCanopyLightVoxels); ++z)
      for (int y = 0; y < int(kCanopyLightVoxels); ++y)
        for (int x = 0; x < int(kCanopyLightVoxels); ++x) {
          int v[3] = {x - 1, y - 1, z - 1};
          int n = 0;
          for (int a = 0, mul = 1; a < 3; ++a, mul *= 3) n += ((v[a] < 0 ? -1 : (v[a] >= kL ? 1 : 0)) + 1) * mul;
          if (!has[n]) {  // repeat this block's edge voxel
            n = 13;
            for (int a = 0; a < 3; ++a) v[a] = std::min(std::max(v[a], 0), kL - 1);
          }
          const int li = lightIndex((v[0] + kL) % kL, (v[1] + kL) % kL, (v[2] + kL) % kL);
          const size_t si = size_t(x) + kCanopyLightVoxels * (size_t(y) + kCanopyLightVoxels * size_t(z));
          const LightBlock& B = nb[n];
          for (uint32_t b = 0; b < kCanopyLightBases; ++b)
            item[b * kCanopyLightVoxelCount + si] = rgb9e5Encode(B.v[3 * b][li], B.v[3 * b + 1][li], B.v[3 * b + 2][li]);
        }
  });
}

// Light levels aligned with the density levels (lights[d].blocks[i] belongs to levels[d].keys[i]),
// then one light item per brick.
// `levels` are the light levels (0..depth - detailLevels); `bricks` the bricks that get items.
void buildLight(const ModelSource& src, const std::string& what, const LightFn& light, const std::vector<Level>& levels,
                const std::vector<std::pair<uint32_t, uint64_t>>& bricks, std::vector<uint32_t>& out) {
  const size_t depth = levels.size() - 1;
  std::vector<std::vector<LightBlock>> lights(levels.size());
  finestLight(src, what, light, levels[depth], lights[depth]);
  for (int d = int(depth) - 1; d >= 0; --d) {
    coarserLight(levels[size_t(d)], levels[size_t(d) + 1], lights[size_t(d) + 1], lights[size_t(d)]);
    // Availability is decided from the level below before any filling (filled values are not
    // "available" for the level above).
  }
  lightItems(levels, lights, bricks, out);
}

}  // namespace

LightFn chaarLightFn(const haar::ChaarView& view) {
  return [view](int32_t i, int32_t j, int32_t k, float* o) {
    const int32_t p[3] = {i, j, k};
    bool inside = true;
    for (int a = 0; a < 3; ++a) inside = inside && p[a] >= view.latticeMin[a] && p[a] <= view.latticeMax[a];
    for (uint32_t b = 0; b < kCanopyLightBases; ++b) {
      haar::Rgb v;
      if (inside) v = haar::chaarSample(view, int(b), float(i), float(j), float(k));
      o[3 * b] = v.r, o[3 * b + 1] = v.g, o[3 * b + 2] = v.b;
    }
  };
}

uint32_t depthForCells(int64_t maxDim) {
  uint32_t depth = 0;
  while ((int64_t(kCanopyBrickSize) << depth) < maxDim) ++depth;
  return depth;
}

namespace {

// A brick node: its level and block key (bricks are listed in brick id order).
struct BrickRef {
  uint32_t level;
  uint64_t key;
};

// The model record's fields that the build knows (the writer sets the rest), and the occupied cells.
void describeModel(const ModelSource& src, uint32_t depth, const Level& finest, BuiltModel& out) {
  out.sourceLabel = src.sourceLabel;
  for (const Block& b : finest.blocks)
    for (int i = 0; i < kBlockVoxels; ++i) out.occupiedCells += b.d[i] != 0.0f;
  CanopyModel& M = out.record;
  std::memset(&M, 0, sizeof M);
  for (int i = 0; i < 12; ++i) M.indexToModel[i] = src.indexToModel[size_t(i)];
  std::strncpy(M.name, src.name.c_str(), sizeof M.name - 1);
  for (int a = 0; a < 3; ++a) {
    M.latticeMin[a] = src.latticeMin[a];
    M.latticeMax[a] = src.latticeMax[a];
    M.octreeOrigin[a] = src.latticeMin[a];
  }
  M.depth = depth;
  M.detailLevels = src.detailLevels;
  M.rootCells = kCanopyBrickSize << depth;
  M.brickSize = kCanopyBrickSize;
  M.brickBorder = kCanopyBrickBorder;
}

// Breadth-first node assignment: the root, node tiles and brick ids; returns the bricks in id order.
std::vector<BrickRef> assignNodes(const std::vector<Level>& levels, uint32_t depth, BuiltModel& out) {
  CanopyModel& M = out.record;
  // Each queue entry: (level, block key, where to store the node).
  struct Pending {
    uint32_t level;
    uint64_t key;
    int64_t slot;  // -1 = root, else index into out.tiles
  };
  std::vector<BrickRef> bricks;  // in brick id order
  std::vector<Pending> queue{{0, packKey(0, 0, 0), -1}};
  for (size_t qi = 0; qi < queue.size(); ++qi) {
    const Pending p = queue[qi];
    CanopyNode n{kCanopyNone, kCanopyNone, 0.0f, 0u};
    if (const Block* b = levels[p.level].find(p.key)) {
      if (b->constant) {
        n.density = b->d[0];
        n.material = b->m[0];
      } else {
        n.brick = uint32_t(bricks.size());
        bricks.push_back({p.level, p.key});
        ++M.levelBricks[p.level];
        blockMean(*b, n.density, n.material);
        if (p.level < depth) {
          n.child = uint32_t(out.tiles.size() / 8);
          ++M.levelTiles[p.level + 1];
          out.tiles.resize(out.tiles.size() + 8);
          uint32_t k[3];
          unpackKey(p.key, k);
          for (uint32_t c = 0; c < 8; ++c)
            queue.push_back({p.level + 1, packKey(2 * k[0] + (c & 1), 2 * k[1] + ((c >> 1) & 1), 2 * k[2] + ((c >> 2) & 1)),
                             int64_t(n.child) * 8 + c});
        }
      }
    }
    if (p.slot < 0) M.root = n;
    else out.tiles[size_t(p.slot)] = n;
  }
  M.tileCount = uint32_t(out.tiles.size() / 8);
  M.brickCount = uint32_t(bricks.size());
  return bricks;
}

// Brick voxels: interior + one-voxel border from the same level (0 outside the lattice/octree).
void writeBricks(const std::vector<Level>& levels, const std::vector<BrickRef>& bricks, BuiltModel& out) {
  out.bricks.assign(size_t(out.record.brickCount) * kCanopyBrickBytes, 0);
  parallelFor(int64_t(bricks.size()), [&](int64_t bi) {
    const BrickRef& br = bricks[size_t(bi)];
    const Level& L = levels[br.level];
    const int64_t blocksPerAxis = int64_t(1) << br.level;
    uint32_t k[3];
    unpackKey(br.key, k);
    const Block* nb[27];  // neighbour blocks, index (dx+1) + 3(dy+1) + 9(dz+1)
    for (int i = 0; i < 27; ++i) {
      const int64_t x = int64_t(k[0]) + i % 3 - 1, y = int64_t(k[1]) + (i / 3) % 3 - 1, z = int64_t(k[2]) + i / 9 - 1;
      const bool inside = x >= 0 && y >= 0 && z >= 0 && x < blocksPerAxis && y < blocksPerAxis && z < blocksPerAxis;
      nb[i] = inside ? L.find(packKey(uint32_t(x), uint32_t(y), uint32_t(z))) : nullptr;
    }
    unsigned char* base = out.bricks.data() + size_t(bi) * kCanopyBrickBytes;
    float* dens = reinterpret_cast<float*>(base);
    uint32_t* mat = reinterpret_cast<uint32_t*>(base + kCanopyBrickVoxelCount * sizeof(float));
    for (int z = 0; z < int(kCanopyBrickVoxels); ++z)
      for (int y = 0; y < int(kCanopyBrickVoxels); ++y)
        for (int x = 0; x < int(kCanopyBrickVoxels); ++x) {
          const int v[3] = {x - 1, y - 1, z - 1};  // voxel relative to this block, -1..8
          int n = 0, li[3];
          for (int a = 0, mul = 1; a < 3; ++a, mul *= 3) {
            const int off = v[a] < 0 ? -1 : (v[a] >= kB ? 1 : 0);
            n += (off + 1) * mul;
            li[a] = v[a] - off * kB;
          }
          const uint32_t idx = canopyVoxelIndex(uint32_t(x), uint32_t(y), uint32_t(z));
          if (const Block* b = nb[n]) {
            const int l = localIndex(li[0], li[1], li[2]);
            dens[idx] = b->d[l];
            mat[idx] = b->m[l];
          }
        }
  });
}

}  // namespace

BuiltModel buildOctree(const ModelSource& src, const std::string& what, const LightFn& light) {
  checkSource(src, what);
  int64_t maxDim = 0;
  for (int a = 0; a < 3; ++a) maxDim = std::max<int64_t>(maxDim, int64_t(src.latticeMax[a]) - src.latticeMin[a] + 1);
  const uint32_t depth = depthForCells(maxDim);
  if (src.detailLevels > depth) throw invalidInput(what + ": more detail levels than the octree has levels");

  // Levels, finest first; levels[d] is level d.
  std::vector<Level> levels(depth + 1);
  levels[depth] = finestLevel(src, what);
  for (int d = int(depth) - 1; d >= 0; --d) levels[size_t(d)] = coarserLevel(levels[size_t(d) + 1]);

  BuiltModel out;
  describeModel(src, depth, levels[depth], out);
  const std::vector<BrickRef> bricks = assignNodes(levels, depth, out);
  writeBricks(levels, bricks, out);
  if (light) {
    // Items for the light levels' bricks: the first ones (breadth-first ids, coarse to fine).
    const uint32_t lightDepth = depth - src.detailLevels;
    std::vector<std::pair<uint32_t, uint64_t>> refs;
    for (const BrickRef& b : bricks)
      if (b.level <= lightDepth) refs.emplace_back(b.level, b.key);
    levels.resize(lightDepth + 1);  // the detail levels' blocks are written: free them
    buildLight(src, what, light, levels, refs, out.light);
    out.record.lightCount = uint32_t(refs.size());
    out.record.flags |= kCanopyModelHasLight;
  }
  return out;
}

}  // namespace canopy::octreepack
