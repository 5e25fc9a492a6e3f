// test_octreepack.cpp: the packer end to end (VDB in, .canopy out), read back through the format's
// CANOPY_HD sampling functions, plus the CLI contract (exit codes, no output left behind).
//
// Tolerances: density is stored as float32 and must come back exactly at the finest level and
// within 1e-6 (float rounding of the double mean) on the MIP levels; albedo and wood are unorm8,
// so they come back within 0.5/255 of the source (plus 1e-6 for float rounding).
#include <gtest/gtest.h>

#include <filesystem>

#include <sys/stat.h>

#include <algorithm>
#include <array>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <random>
#include <string>

#include <openvdb/openvdb.h>
#include <tbb/global_control.h>

#include "canopy/atomic_file.h"
#include "canopy/hash.h"
#include "formats/canopy_file.h"
#include "formats/canopy_write.h"
#include "formats/lattice_vdb.h"
#include "formats/scene_json.h"
#include "gltf_scene.h"
#include "tests/octreepack/packed_sampler.h"
#include "tests/octreepack/source_vdb.h"
#include "tests/octreepack/synthetic.h"
#include "tools/octreepack/inputs.h"
#include "tools/octreepack/octreepack.h"

namespace op = canopy::octreepack;
using canopy::CanopyFile;
using canopy::CanopySample;
using op::testing::PackedSampler;
using op::testing::syntheticPlant;
using op::testing::kNoMesh;
using op::testing::writeSourceVdb;

namespace {

constexpr float kQuant = 0.5f / 255.0f + 1e-6f;

std::string tmpDir() {
  static std::string dir = [] {
    std::string d = std::string(CANOPY_BINARY_DIR) + "/tests/octreepack/tmp";
    std::string cmd = "mkdir -p '" + d + "'";
    EXPECT_EQ(std::system(cmd.c_str()), 0);
    return d;
  }();
  return dir;
}

// An lbsolve-style light VDB: 19 Vec3 grids B00..B18 holding analyticLight over an n^3 lattice.
// scatteredSun: how many of the sun bases B01.. carry canopy_direct_beam = false (lbsolve's
// default marks all 18; 0: no metadata, as light files from before it). indexToModel (optional):
// the grids' transform (3x4 row-major) and the lattice metadata of [0, n)^3 (none without it).
void writeLightVdb(const std::string& path, int n, uint32_t scatteredSun = 0, const std::array<double, 12>* indexToModel = nullptr) {
  openvdb::Mat4d m = openvdb::Mat4d::identity();
  if (indexToModel)
    for (int r = 0; r < 3; ++r)
      for (int c = 0; c < 4; ++c) m(c, r) = (*indexToModel)[size_t(r * 4 + c)];  // OpenVDB: row vectors
  openvdb::GridPtrVec grids;
  float tmp[canopy::kCanopyLightChannels];
  for (uint32_t b = 0; b < canopy::kCanopyLightBases; ++b) {
    auto g = openvdb::Vec3SGrid::create(openvdb::Vec3s(0.0f));
    char name[8];
    std::snprintf(name, sizeof name, "B%02u", b);
    g->setName(name);
    auto acc = g->getAccessor();
    for (int k = 0; k < n; ++k)
      for (int j = 0; j < n; ++j)
        for (int i = 0; i < n; ++i) {
          op::testing::analyticLight(i, j, k, tmp);
          acc.setValue(openvdb::Coord(i, j, k), openvdb::Vec3s(tmp[3 * b], tmp[3 * b + 1], tmp[3 * b + 2]));
        }
    if (scatteredSun > 0) g->insertMeta("canopy_direct_beam", openvdb::BoolMetadata(b == 0 || b > scatteredSun));
    if (indexToModel) {
      g->setTransform(openvdb::math::Transform::createLinearTransform(m));
      canopy::vdbio::LatticeMeta lm;
      lm.min = openvdb::Coord(0);
      lm.max = openvdb::Coord(n - 1);
      lm.source = "test";
      canopy::vdbio::stampGrid(*g, lm);
    }
    grids.push_back(g);
  }
  canopy::vdbio::writeVdb(path, grids);
}

std::string packVdb(const std::string& vdb, const std::string& out) {
  op::OctreepackOptions o;
  o.inputs = {vdb};
  o.output = out;
  op::octreepack(o);
  return out;
}

std::string packPlant(const op::ModelSource& s, const std::string& stem) {
  const std::string vdb = tmpDir() + "/" + stem + ".density.vdb";
  writeSourceVdb(vdb, s);
  return packVdb(vdb, tmpDir() + "/" + stem + ".canopy");
}

std::vector<unsigned char> bytesOf(const std::string& p) { return canopy::readFile(p); }

int run(const std::string& args) {
  const std::string cmd = std::string(CANOPY_BINARY_DIR) + "/bin/canopy-octreepack " + args + " >/dev/null 2>&1";
  const int rc = std::system(cmd.c_str());
  return WIFEXITED(rc) ? WEXITSTATUS(rc) : -1;
}

bool exists(const std::string& p) {
  struct stat st;
  return stat(p.c_str(), &st) == 0;
}

const op::ModelSource& plant() {
  static op::ModelSource s = syntheticPlant(40, -3, "plant");
  return s;
}

const std::string& plantFile() {
  static std::string f = packPlant(plant(), "plant");
  return f;
}

}  // namespace

TEST(Octreepack, FinestLevelRoundTripsEveryOccupiedCell) {
  CanopyFile f = CanopyFile::open(plantFile());
  ASSERT_EQ(f.modelCount(), 1u);
  ASSERT_EQ(f.instanceCount(), 1u);
  const canopy::CanopyModel& M = f.model(0);
  EXPECT_EQ(M.depth, 3u);  // 40 cells -> 8 * 2^3 = 64
  EXPECT_EQ(std::string(M.name), "plant");
  EXPECT_DOUBLE_EQ(M.indexToModel[3], 0.1);
  PackedSampler S(f);
  size_t checked = 0;
  for (const auto& c : plant().cells) {
    const CanopySample v = S.sampleLattice(0, float(c.ijk[0]), float(c.ijk[1]), float(c.ijk[2]));
    ASSERT_EQ(v.density, c.density) << "cell " << c.ijk[0] << "," << c.ijk[1] << "," << c.ijk[2];
    ASSERT_NEAR(v.wood, c.wood, kQuant);
    for (int a = 0; a < 3; ++a) ASSERT_NEAR(v.albedo[a], c.albedo[a], kQuant);
    ++checked;
  }
  EXPECT_GT(checked, 5000u);
}

TEST(Octreepack, UnoccupiedCellsAreEmpty) {
  CanopyFile f = CanopyFile::open(plantFile());
  PackedSampler S(f);
  std::vector<char> occ(40 * 40 * 40, 0);
  for (const auto& c : plant().cells) occ[size_t((c.ijk[0] + 3) + 40 * ((c.ijk[1] + 3) + 40 * (c.ijk[2] + 3)))] = 1;
  for (int k = 0; k < 40; k += 3)
    for (int j = 0; j < 40; ++j)
      for (int i = 0; i < 40; ++i)
        if (!occ[size_t(i + 40 * (j + 40 * k))]) {
          ASSERT_EQ(S.sampleLattice(0, float(i - 3), float(j - 3), float(k - 3)).density, 0.0f);
        }
}

// Trilinear sampling between cell centres, including across brick boundaries (the border voxels),
// equals trilinear interpolation of the source lattice (0 outside it).
TEST(Octreepack, TrilinearSamplesMatchSourceAcrossBrickBorders) {
  CanopyFile f = CanopyFile::open(plantFile());
  PackedSampler S(f);
  std::vector<float> dense(40 * 40 * 40, 0.0f);
  for (const auto& c : plant().cells) dense[size_t((c.ijk[0] + 3) + 40 * ((c.ijk[1] + 3) + 40 * (c.ijk[2] + 3)))] = c.density;
  auto at = [&](int i, int j, int k) {
    i += 3, j += 3, k += 3;
    return (i < 0 || j < 0 || k < 0 || i >= 40 || j >= 40 || k >= 40) ? 0.0f : dense[size_t(i + 40 * (j + 40 * k))];
  };
  std::mt19937 rng(7);
  std::uniform_real_distribution<float> U(-3.0f, 36.0f);
  int acrossBorder = 0;
  for (int n = 0; n < 20000; ++n) {
    const float p[3] = {U(rng), U(rng), U(rng)};
    int i0[3];
    float fr[3];
    for (int a = 0; a < 3; ++a) {
      i0[a] = int(std::floor(p[a]));
      fr[a] = p[a] - float(i0[a]);
    }
    if (((i0[0] + 3) & 7) == 7 || ((i0[1] + 3) & 7) == 7 || ((i0[2] + 3) & 7) == 7) ++acrossBorder;
    double ref = 0;
    for (int c = 0; c < 8; ++c) {
      const int dx = c & 1, dy = (c >> 1) & 1, dz = c >> 2;
      ref += double((dx ? fr[0] : 1 - fr[0]) * (dy ? fr[1] : 1 - fr[1]) * (dz ? fr[2] : 1 - fr[2])) *
             at(i0[0] + dx, i0[1] + dy, i0[2] + dz);
    }
    const CanopySample v = S.sampleLattice(0, p[0], p[1], p[2]);
    // Inside a constant node the packed model returns the constant (no neighbour blending across
    // its faces: GigaVoxels §6.1.6); the synthetic core is surrounded by equal values one cell deep
    // only where the uniform region continues, so compare only where the node holds a brick.
    const canopy::CanopyModel& M = f.model(0);
    float u[3];
    canopy::canopyLatticeToUnit(M.octreeOrigin, M.rootCells, p[0], p[1], p[2], u);
    if (f.descend(0, u[0], u[1], u[2], M.depth).node.brick == canopy::kCanopyNone) continue;
    ASSERT_NEAR(v.density, ref, 2e-6) << p[0] << "," << p[1] << "," << p[2];
  }
  EXPECT_GT(acrossBorder, 2000);
}

// Every voxel of every coarser level is the 2x2x2 box filter of the level below: density averaged,
// albedo and wood density-weighted.
TEST(Octreepack, EveryMipLevelIsABoxFilterOfTheLevelBelow) {
  CanopyFile f = CanopyFile::open(plantFile());
  PackedSampler S(f);
  const canopy::CanopyModel& M = f.model(0);
  size_t nonEmpty = 0;
  for (uint32_t level = 0; level < M.depth; ++level) {
    const int64_t n = int64_t(canopy::kCanopyBrickSize) << level;
    for (int64_t z = 0; z < n; ++z)
      for (int64_t y = 0; y < n; ++y)
        for (int64_t x = 0; x < n; ++x) {
          const int64_t g[3] = {x, y, z};
          const CanopySample p = S.voxel(0, level, g);
          double sd = 0, sw = 0, sa[3] = {0, 0, 0};
          for (int c = 0; c < 8; ++c) {
            const int64_t h[3] = {2 * x + (c & 1), 2 * y + ((c >> 1) & 1), 2 * z + (c >> 2)};
            const CanopySample v = S.voxel(0, level + 1, h);
            sd += v.density;
            sw += double(v.density) * v.wood;
            for (int a = 0; a < 3; ++a) sa[a] += double(v.density) * v.albedo[a];
          }
          ASSERT_NEAR(p.density, sd / 8, 1e-6) << "level " << level << " voxel " << x << "," << y << "," << z;
          if (sd > 0) {
            ++nonEmpty;
            ASSERT_NEAR(p.wood, sw / sd, kQuant);
            for (int a = 0; a < 3; ++a) ASSERT_NEAR(p.albedo[a], sa[a] / sd, kQuant);
          }
        }
  }
  EXPECT_GT(nonEmpty, 500u);
}

TEST(Octreepack, UniformRegionsBecomeConstantNodes) {
  CanopyFile f = CanopyFile::open(plantFile());
  const nlohmann::json info = op::canopyInfo(f);
  uint64_t constant = 0, bricks = 0;
  for (const auto& l : info["models"][0]["levels"]) {
    constant += l["constant_nodes"].get<uint64_t>();
    bricks += l["bricks"].get<uint64_t>();
  }
  EXPECT_GE(constant, 1u);
  EXPECT_EQ(bricks, f.model(0).brickCount);
  EXPECT_LT(info["resident_fraction"].get<double>(), 0.5);  // tiny test file: the 64 KiB resident page dominates
}

TEST(Octreepack, PackingTwiceGivesIdenticalBytesWhateverTheCellOrder) {
  const std::string a = plantFile();
  const std::string b = packVdb(tmpDir() + "/plant.density.vdb", tmpDir() + "/plant_again.canopy");
  EXPECT_EQ(bytesOf(a), bytesOf(b));
  op::ModelSource shuffled = plant();
  std::mt19937 rng(3);
  std::shuffle(shuffled.cells.begin(), shuffled.cells.end(), rng);
  const op::BuiltModel x = op::buildOctree(plant(), "a"), y = op::buildOctree(shuffled, "b");
  EXPECT_EQ(x.bricks, y.bricks);
  EXPECT_EQ(0, std::memcmp(x.tiles.data(), y.tiles.data(), x.tiles.size() * sizeof(canopy::CanopyNode)));
}

TEST(Octreepack, SceneJsonPacksModelsInstancesAndSceneLight) {
  const std::string dir = tmpDir();
  writeSourceVdb(dir + "/a.density.vdb", syntheticPlant(24, 0, "a", 0));
  writeSourceVdb(dir + "/b.density.vdb", syntheticPlant(20, 5, "b", 0));
  // A coarse scene lighting lattice: the float grids B00..B18 of canopy-lbsolve --scene (B00 the
  // ambient factor, B01..B18 the sun bases), base b at (i, j, k) holding 1 + i + 10 j + 100 k + 1000 b.
  openvdb::GridPtrVec bases;
  for (int b = 0; b < 19; ++b) {
    auto light = openvdb::FloatGrid::create(0.0f);
    char name[8];
    std::snprintf(name, sizeof name, "B%02d", b);
    light->setName(name);
    for (int k = 0; k < 3; ++k)
      for (int j = 0; j < 4; ++j)
        for (int i = 0; i < 5; ++i) light->tree().setValue(openvdb::Coord(i, j, k), 1.0f + float(i + 10 * j + 100 * k + 1000 * b));
    light->setTransform(openvdb::math::Transform::createLinearTransform(2.0));
    bases.push_back(light);
  }
  canopy::vdbio::writeVdb(dir + "/scene_light.vdb", bases);
  std::ofstream(dir + "/scene.json") << R"({"canopy_scene": 1,
    "models": [{"name": "a", "density": "a.density.vdb"}, {"name": "b", "density": "b.density.vdb"}],
    "instances": [{"model": 0, "matrix": [1,0,0,0, 0,1,0,0, 0,0,1,0, 0,0,0,1]},
                  {"model": 1, "matrix": [0,0,1,5, 0,1,0,0, -1,0,0,2, 0,0,0,1]},
                  {"model": 0, "matrix": [2,0,0,-4, 0,2,0,0, 0,0,2,1, 0,0,0,1]}]})";
  op::OctreepackOptions o;
  o.scene = dir + "/scene.json";
  o.sceneLight = dir + "/scene_light.vdb";
  o.output = dir + "/scene.canopy";
  o.pageCoding = "lz4";
  EXPECT_THROW(op::octreepack(o), canopy::Error);  // zstd or raw only
  o.pageCoding = "raw";  // the version the content needs (compressed pages are 5.0 whatever they hold)
  const nlohmann::json report = op::octreepack(o);
  CanopyFile f = CanopyFile::open(o.output);
  ASSERT_EQ(f.modelCount(), 2u);
  ASSERT_EQ(f.instanceCount(), 3u);
  EXPECT_EQ(std::string(f.model(1).name), "b");
  EXPECT_EQ(f.instance(1).model, 1u);
  EXPECT_FLOAT_EQ(f.instance(1).modelToWorld[2], 1.0f);
  EXPECT_FLOAT_EQ(f.instance(1).modelToWorld[3], 5.0f);
  EXPECT_FLOAT_EQ(f.instance(2).modelToWorld[0], 2.0f);
  EXPECT_EQ(f.model(1).firstBrickPage, f.model(0).brickPageCount);
  ASSERT_TRUE(f.hasSceneLight());
  EXPECT_EQ(f.sceneLight().dim[0], 5);
  EXPECT_EQ(f.sceneLight().dim[2], 3);
  EXPECT_EQ(f.header().minor, 2);  // the sun bases are a 1.2 feature
  ASSERT_EQ(f.sceneLightBases(), 19u);
  for (int b = 0; b < 19; ++b)  // base-major, every base on the one lattice
    EXPECT_FLOAT_EQ(f.sceneLightValues()[size_t(60 * b + 4 + 5 * (3 + 4 * 2))], 1.0f + 4 + 30 + 200 + 1000 * b) << b;
  EXPECT_DOUBLE_EQ(f.sceneLight().indexToWorld[0], 2.0);
  EXPECT_EQ(report["models"][1]["instances"].get<int>(), 1);
  EXPECT_EQ(report["scene_light_bases"].get<int>(), 19);
  // --scene-light-grid B00: that grid alone, the one static factor (a file without 1.2 features).
  o.sceneLightGrid = "B00";
  o.output = dir + "/scene-b00.canopy";
  const nlohmann::json one = op::octreepack(o);
  CanopyFile g = CanopyFile::open(o.output);
  EXPECT_EQ(g.sceneLightBases(), 1u);
  EXPECT_LT(g.header().minor, 2);
  ASSERT_EQ(g.sceneLightValues().size(), 60u);
  EXPECT_TRUE(std::equal(g.sceneLightValues().begin(), g.sceneLightValues().end(), f.sceneLightValues().begin()));
  EXPECT_EQ(one["scene_light_bases"].get<int>(), 1);
  // Both models sample back exactly.
  PackedSampler S(f);
  const auto b = syntheticPlant(20, 5, "b", 0);
  for (const auto& c : b.cells) ASSERT_EQ(S.sampleLattice(1, float(c.ijk[0]), float(c.ijk[1]), float(c.ijk[2])).density, c.density);
}

// ---- --scene SCENE.glb: lattices matched to the glTF meshes by their metadata --------------------
// Synthetic lattices stamped as canopy-voxelize grove.glb --mesh N stamps them (canopy_source with
// grove.glb's hash, canopy_mesh_index N); grove.glb's nodes use meshes 0, 1, 2 (12 instances).
struct GroveLattices {
  std::string dir, glb, source;
  std::string lattice(int mesh) const { return dir + "/grove.mesh" + std::to_string(mesh) + ".density.vdb"; }
};

const GroveLattices& groveLattices() {
  static const GroveLattices g = [] {
    GroveLattices r;
    r.dir = tmpDir() + "/glb";
    EXPECT_EQ(std::system(("mkdir -p '" + r.dir + "'").c_str()), 0);
    r.glb = std::string(CANOPY_SHARED_DIR) + "/assets/scenes/grove.glb";
    r.source = "elsewhere/grove.glb xxh64:" + canopy::hex64(canopy::hashFile(r.glb));  // the path may differ
    for (int m = 0; m < 3; ++m) writeSourceVdb(r.lattice(m), syntheticPlant(16 + 4 * m, 0, "g", 0), r.source, m);
    writeLightVdb(r.dir + "/grove.mesh1.light.vdb", 20);
    return r;
  }();
  return g;
}

// octreepack() on a glb scene; returns the error's code and message, or Ok.
std::pair<canopy::ExitCode, std::string> packGlb(const std::vector<std::string>& inputs, const std::string& out) {
  op::OctreepackOptions o;
  o.scene = groveLattices().glb;
  o.inputs = inputs;
  o.output = out;
  try {
    op::octreepack(o);
  } catch (const canopy::Error& e) {
    return {e.code(), e.what()};
  }
  return {canopy::ExitCode::Ok, ""};
}

TEST(OctreepackGltf, SceneGlbPacksLikeItsInstanceListByteForByte) {
  const GroveLattices& g = groveLattices();
  // Any order; the lighting follows its lattice.
  const std::string fromGlb = g.dir + "/from_glb.canopy";
  ASSERT_EQ(packGlb({g.lattice(2), g.lattice(0), g.lattice(1), g.dir + "/grove.mesh1.light.vdb"}, fromGlb).second, "");
  // The instance list canopy-voxelize --instances writes (same function), with the same paths.
  canopy::Scene list = canopy::mesh::sceneFromGltf(g.glb);
  canopy::mesh::applyModelPattern(list, g.glb, g.dir + "/{stem}.mesh{N}.density.vdb");
  list.models[1].light = g.dir + "/grove.mesh1.light.vdb";
  canopy::writeSceneJson(g.dir + "/grove.scene.json", list);
  op::OctreepackOptions o;
  o.scene = g.dir + "/grove.scene.json";
  o.output = g.dir + "/from_json.canopy";
  op::octreepack(o);
  EXPECT_EQ(bytesOf(fromGlb), bytesOf(o.output));

  CanopyFile f = CanopyFile::open(fromGlb);
  ASSERT_EQ(f.modelCount(), 3u);
  ASSERT_EQ(f.instanceCount(), 12u);
  EXPECT_EQ(std::string(f.model(0).name), "Oak Medium");
  EXPECT_EQ(f.model(2).latticeMax[0], 16 + 4 * 2 - 1);  // mesh 2's lattice went to model 2
  EXPECT_TRUE(f.model(1).flags & canopy::kCanopyModelHasLight);
  EXPECT_FALSE(f.model(0).flags & canopy::kCanopyModelHasLight);
  for (uint32_t i = 0; i < f.instanceCount(); ++i) {
    ASSERT_EQ(f.instance(i).model, list.instances[i].model);
    for (int k = 0; k < 12; ++k) ASSERT_EQ(f.instance(i).modelToWorld[k], float(list.instances[i].matrix[size_t(k)]));
  }
  EXPECT_EQ(nlohmann::json::parse(f.metadata())["scene"], list.source);
}

TEST(OctreepackGltf, LatticesThatDoNotFitTheSceneAreRejected) {
  const GroveLattices& g = groveLattices();
  const std::string out = g.dir + "/bad.canopy";
  std::remove(out.c_str());
  auto expectError = [&](const std::vector<std::string>& inputs, canopy::ExitCode code, const std::string& want) {
    const auto [c, what] = packGlb(inputs, out);
    EXPECT_EQ(c, code) << what;
    EXPECT_NE(what.find(want), std::string::npos) << what;
    EXPECT_EQ(what.find('\n'), std::string::npos) << what;
    EXPECT_FALSE(exists(out));
  };
  expectError({g.lattice(0), g.lattice(2)}, canopy::ExitCode::InvalidInput,
              "grove.glb: mesh 1 ('Pine Small') has no lattice among the inputs (canopy-voxelize ");
  expectError({g.lattice(0), g.lattice(2)}, canopy::ExitCode::InvalidInput, "--mesh 1 -o grove.mesh1.density.vdb)");
  expectError({g.lattice(0), g.lattice(1), g.lattice(2), g.lattice(1)}, canopy::ExitCode::InvalidInput,
              "grove.mesh1.density.vdb: mesh 1 ('Pine Small') already has a lattice (");
  writeSourceVdb(g.dir + "/foreign.density.vdb", syntheticPlant(16, 0, "f", 0), "oak.glb xxh64:0123456789abcdef", 0);
  expectError({g.lattice(0), g.lattice(1), g.lattice(2), g.dir + "/foreign.density.vdb"}, canopy::ExitCode::InvalidInput,
              "foreign.density.vdb: voxelised from 'oak.glb xxh64:0123456789abcdef', not from the scene ");
  writeSourceVdb(g.dir + "/whole.density.vdb", syntheticPlant(16, 0, "w", 0), g.source, -1);
  expectError({g.dir + "/whole.density.vdb"}, canopy::ExitCode::InvalidInput, "whole.density.vdb: voxelised from the whole of ");
  writeSourceVdb(g.dir + "/unused.density.vdb", syntheticPlant(16, 0, "u", 0), g.source, 7);
  expectError({g.dir + "/unused.density.vdb"}, canopy::ExitCode::InvalidInput,
              "unused.density.vdb: voxelised from mesh 7, which no node of ");
  expectError({g.dir + "/grove.mesh1.light.vdb", g.lattice(1)}, canopy::ExitCode::Usage,
              "a lighting input must follow the density lattice it lights");
  expectError({}, canopy::ExitCode::Usage, "give the density lattice of each of its 3 meshes");
  expectError({g.lattice(0), g.dir + "/missing.density.vdb"}, canopy::ExitCode::Io, "missing.density.vdb");
  canopy::writeFileAtomic(g.dir + "/garbage.density.vdb", std::string("this is not a vdb"));
  expectError({g.dir + "/garbage.density.vdb"}, canopy::ExitCode::InvalidInput, "garbage.density.vdb: not a readable OpenVDB file");
}

TEST(OctreepackGltf, CliExitCodesAndNoOutputLeftBehind) {
  const GroveLattices& g = groveLattices();
  const std::string out = g.dir + "/cli.canopy";
  std::remove(out.c_str());
  const std::string scene = "--scene '" + g.glb + "' ";
  EXPECT_EQ(run(scene + "'" + g.lattice(0) + "' '" + g.lattice(1) + "' -o '" + out + "'"), 3);  // mesh 2 missing
  EXPECT_EQ(run(scene + "-o '" + out + "'"), 1);                                                   // no lattices
  EXPECT_EQ(run("--scene '" + g.dir + "/grove.scene.json' '" + g.lattice(0) + "' -o '" + out + "'"), 1);  // JSON + lattices
  EXPECT_FALSE(exists(out));
  EXPECT_EQ(run(scene + "'" + g.lattice(1) + "' '" + g.lattice(2) + "' '" + g.lattice(0) + "' -o '" + out + "'"), 0);
  EXPECT_EQ(run("verify '" + out + "'"), 0);
}

// The parallel builder's bytes do not depend on the number of threads (lit, to cover the light
// pyramid too).
TEST(Octreepack, BytesDoNotDependOnTheThreadCount) {
  auto packBytes = [] {
    const op::BuiltModel m = op::buildOctree(syntheticPlant(40, -3, "threads"), "threads", op::testing::analyticLight);
    canopy::CanopyWriteInput in;
    in.models.push_back({m.record, &m.tiles, &m.bricks, &m.light});
    return canopy::writeCanopyBytes(std::move(in));
  };
  const std::vector<unsigned char> parallel = packBytes();
  std::vector<unsigned char> serial;
  {
    tbb::global_control one(tbb::global_control::max_allowed_parallelism, 1);
    serial = packBytes();
  }
  EXPECT_EQ(parallel, serial);
}

// World -> octree unit space of an instance (what a player uses to start a ray in a model): the
// model-space centre of a lattice cell, moved by the instance, maps back to that cell's unit point.
TEST(Octreepack, WorldToUnitInvertsInstanceAndModelTransforms) {
  CanopyFile f = CanopyFile::open(plantFile());
  canopy::CanopyModel M = f.model(0);
  canopy::CanopyInstance inst{};
  const float yaw = 0.7f, s = 1.3f;
  const float m[12] = {s * std::cos(yaw), 0, s * std::sin(yaw), 4.0f, 0, s, 0, -1.0f, -s * std::sin(yaw), 0, s * std::cos(yaw), 2.5f};
  std::memcpy(inst.modelToWorld, m, sizeof m);
  float w2u[12];
  ASSERT_TRUE(canopy::canopyWorldToUnit(M, inst, w2u));
  for (const auto& c : {plant().cells[0], plant().cells[1000], plant().cells.back()}) {
    float pm[3];
    for (int r = 0; r < 3; ++r)
      pm[r] = float(M.indexToModel[4 * r] * c.ijk[0] + M.indexToModel[4 * r + 1] * c.ijk[1] + M.indexToModel[4 * r + 2] * c.ijk[2] +
                    M.indexToModel[4 * r + 3]);
    float pw[3], u[3], want[3];
    canopy::canopyTransformPoint(inst.modelToWorld, pm, pw);
    canopy::canopyTransformPoint(w2u, pw, u);
    canopy::canopyLatticeToUnit(M.octreeOrigin, M.rootCells, float(c.ijk[0]), float(c.ijk[1]), float(c.ijk[2]), want);
    for (int a = 0; a < 3; ++a) ASSERT_NEAR(u[a], want[a], 1e-5f);
  }
  canopy::CanopyInstance flat = inst;
  flat.modelToWorld[5] = 0;  // singular
  EXPECT_FALSE(canopy::canopyWorldToUnit(M, flat, w2u));
}

// ---- CLI contract ---------------------------------------------------------------------------------
TEST(OctreepackCli, InfoAndVerifyOnAGoodFile) {
  const std::string f = plantFile();
  EXPECT_EQ(run("info '" + f + "'"), 0);
  EXPECT_EQ(run("info '" + f + "' --json"), 0);
  EXPECT_EQ(run("verify '" + f + "'"), 0);
  EXPECT_EQ(run("--help"), 0);
  EXPECT_EQ(run("--version"), 0);
}

TEST(OctreepackCli, VerifyFailsOnCorruptTruncatedAndNewerFiles) {
  const std::vector<unsigned char> good = bytesOf(plantFile());
  const std::string dir = tmpDir();
  auto writeVariant = [&](const std::string& name, std::vector<unsigned char> bytes) {
    canopy::writeFileAtomic(dir + "/" + name, bytes.data(), bytes.size());
    return dir + "/" + name;
  };
  canopy::CanopyFileHeader h;
  std::memcpy(&h, good.data(), sizeof h);
  // A flipped byte in the last page (compressed, as canopy-octreepack writes by default: in its
  // Zstandard frame, which the CRC of its stored bytes catches before it is decoded).
  ASSERT_EQ(h.pageCoding, canopy::kCanopyPageZstd);
  std::vector<unsigned char> flipped = good;
  flipped.at(good.size() - 16) ^= 0x10;
  EXPECT_EQ(run("verify '" + writeVariant("flipped.canopy", flipped) + "'"), 3);
  EXPECT_EQ(run("info '" + dir + "/flipped.canopy'"), 0);  // info reads the resident part only
  // Truncated at several points.
  for (size_t n : {size_t(0), size_t(100), size_t(h.pagesOffset), good.size() - 1})
    EXPECT_EQ(run("verify '" + writeVariant("trunc.canopy", std::vector<unsigned char>(good.begin(), good.begin() + long(n))) + "'"), 3) << n;
  // Newer major version (header CRC recomputed so only the version is wrong).
  std::vector<unsigned char> newer = good;
  canopy::CanopyFileHeader nh = h;
  nh.major = canopy::kCanopyMajor + 1;
  nh.headerCrc = canopy::crc32(0, &nh, offsetof(canopy::CanopyFileHeader, headerCrc));
  std::memcpy(newer.data(), &nh, sizeof nh);
  EXPECT_EQ(run("verify '" + writeVariant("newer.canopy", newer) + "'"), 5);
  EXPECT_EQ(run("verify '" + dir + "/does-not-exist.canopy'"), 2);
}

TEST(OctreepackCli, BadInputsFailCleanlyAndLeaveNoOutput) {
  const std::string dir = tmpDir();
  writeSourceVdb(dir + "/cli.density.vdb", syntheticPlant(16, 0, "cli", 0));
  const std::string out = dir + "/cli-out.canopy";
  std::remove(out.c_str());
  EXPECT_EQ(run("'" + dir + "/missing.density.vdb' -o '" + out + "'"), 2);
  EXPECT_EQ(run("'" + dir + "/cli.density.vdb'"), 1);                             // no -o
  EXPECT_EQ(run("--no-such-flag"), 1);
  EXPECT_EQ(run("'" + dir + "/cli.density.vdb' -o /nonexistent-dir/x.canopy"), 2);  // unwritable
  std::ofstream(dir + "/not.vdb") << "this is not a vdb";
  EXPECT_EQ(run("'" + dir + "/not.vdb' -o '" + out + "'"), 3);
  std::ofstream(dir + "/p.light.chaar") << "x";
  // A corrupt .chaar (3).
  EXPECT_EQ(run("'" + dir + "/cli.density.vdb' '" + dir + "/p.light.chaar' -o '" + out + "'"), 3);
  EXPECT_EQ(run("--scene '" + dir + "/not-a-scene.glb' -o '" + out + "'"), 2);  // missing glTF
  std::ofstream(dir + "/corrupt.glb") << "glTF garbage";
  EXPECT_EQ(run("--scene '" + dir + "/corrupt.glb' '" + dir + "/cli.density.vdb' -o '" + out + "'"), 3);
  std::ofstream(dir + "/bad.scene.json") << R"({"canopy_scene": 1, "models": [{"density": "cli.density.vdb"}], "instances": [{"model": 3, "matrix": [1,0,0,0,0,1,0,0,0,0,1,0,0,0,0,1]}]})";
  EXPECT_EQ(run("--scene '" + dir + "/bad.scene.json' -o '" + out + "'"), 3);
  EXPECT_FALSE(exists(out));
  // The same plant with --ignore-light packs.
  EXPECT_EQ(run("'" + dir + "/cli.density.vdb' '" + dir + "/p.light.chaar' --ignore-light -o '" + out + "'"), 0);
  EXPECT_TRUE(exists(out));
  EXPECT_EQ(run("verify '" + out + "'"), 0);
}

// canopy-lbsolve and canopy-octreepack read scene lists with the same reader (formats/scene_json.h):
// the same bad list gets the same exit code and the same one-line message from both.
TEST(OctreepackCli, SceneListErrorsAreTheSameAsLbsolves) {
  const std::string lbsolve = std::string(CANOPY_BINARY_DIR) + "/bin/canopy-lbsolve";
  if (!exists(lbsolve)) GTEST_SKIP() << "canopy-lbsolve is not built";
  const std::string dir = tmpDir();
  writeSourceVdb(dir + "/same.density.vdb", syntheticPlant(16, 0, "same", 0));
  // Runs a tool; returns its exit code and its stderr from "error: " on.
  auto errorOf = [](const std::string& cmd) {
    FILE* p = popen((cmd + " 2>&1 >/dev/null").c_str(), "r");
    std::string text;
    char buf[512];
    while (p && std::fgets(buf, sizeof buf, p)) text += buf;
    const int rc = p ? pclose(p) : -1;
    const auto at = text.find("error: ");
    return std::make_pair(WIFEXITED(rc) ? WEXITSTATUS(rc) : -1, at == std::string::npos ? text : text.substr(at));
  };
  const std::string identity = "[1,0,0,0, 0,1,0,0, 0,0,1,0, 0,0,0,1]";
  const std::pair<std::string, int> cases[] = {
      {R"({"canopy_scene": 1, "models": [{"density": "same.density.vdb"}], "instances": [{"model": 3, "matrix": )" + identity + "}]}", 3},
      {R"({"canopy_scene": 1, "models": [{"density": "same.density.vdb"}], "instances": [{"model": 0, "matrix": [1,0,0,0, 0,0,0,0, 0,0,1,0, 0,0,0,1]}]})", 3},
      {R"({"canopy_scene": 2, "models": [{"density": "same.density.vdb"}], "instances": [{"model": 0, "matrix": )" + identity + "}]}", 5},
      {R"({"canopy_scene": 1, "models": [{"density": "same.density.vdb"}], "instances": [{"model": 0, "matrix": )" + identity, 3},
  };
  for (const auto& [text, code] : cases) {
    canopy::writeFileAtomic(dir + "/same.scene.json", text);
    const auto a = errorOf(std::string(CANOPY_BINARY_DIR) + "/bin/canopy-octreepack --scene '" + dir + "/same.scene.json' -o '" + dir + "/same.canopy'");
    const auto b = errorOf(lbsolve + " --scene '" + dir + "/same.scene.json' -o '" + dir + "/same.light.vdb'");
    EXPECT_EQ(a.first, code) << text;
    EXPECT_EQ(a, b) << text;
    EXPECT_NE(a.second.find(dir + "/same.scene.json: "), std::string::npos) << a.second;
    EXPECT_FALSE(exists(dir + "/same.canopy"));
    EXPECT_FALSE(exists(dir + "/same.light.vdb"));
  }
}

// What canopy-lbsolve --scene writes packs by default: its 19 bases B00..B18 (format 1.2), B00 first
// and the same as --scene-light-grid B00 packs alone (before format 1.2, the only factor). `info`
// tells them apart. (Before 2026-12 the default grid was "light", which lbsolve never writes.)
TEST(OctreepackCli, LbsolveSceneLightPacksItsNineteenBasesByDefault) {
  const std::string lbsolve = std::string(CANOPY_BINARY_DIR) + "/bin/canopy-lbsolve";
  if (!exists(lbsolve)) GTEST_SKIP() << "canopy-lbsolve is not built";
  const std::string dir = tmpDir();
  writeSourceVdb(dir + "/lit.density.vdb", syntheticPlant(16, 0, "lit", 0));
  canopy::writeFileAtomic(dir + "/lit.scene.json", std::string(R"({"canopy_scene": 1, "models": [{"density": "lit.density.vdb"}],
    "instances": [{"model": 0, "matrix": [1,0,0,0, 0,1,0,0, 0,0,1,0, 0,0,0,1]},
                  {"model": 0, "matrix": [1,0,0,2, 0,1,0,0, 0,0,1,0, 0,0,0,1]}]})"));
  const std::string sceneLight = dir + "/lit.scenelight.vdb", out = dir + "/lit.canopy";
  std::remove(out.c_str());
  ASSERT_EQ(std::system((lbsolve + " --scene '" + dir + "/lit.scene.json' -o '" + sceneLight +
                         "' --scene-resolution 8 --device cpu -q").c_str()), 0);
  ASSERT_EQ(run("--scene '" + dir + "/lit.scene.json' --scene-light '" + sceneLight + "' -o '" + out + "'"), 0);
  const CanopyFile all = CanopyFile::open(out);
  ASSERT_TRUE(all.hasSceneLight());
  EXPECT_EQ(all.sceneLightBases(), 19u);
  const std::string named = dir + "/lit-b00.canopy";
  ASSERT_EQ(run("--scene '" + dir + "/lit.scene.json' --scene-light '" + sceneLight + "' --scene-light-grid B00 -o '" + named + "'"), 0);
  const CanopyFile one = CanopyFile::open(named);
  EXPECT_EQ(one.sceneLightBases(), 1u);
  const size_t n = one.sceneLightValues().size();
  ASSERT_EQ(all.sceneLightValues().size(), 19 * n);
  EXPECT_TRUE(std::equal(one.sceneLightValues().begin(), one.sceneLightValues().end(), all.sceneLightValues().begin()));
  // lbsolve's sun bases are factors of an unoccluded 1: the one from above (B04) is 1 on the top
  // layer of nodes (nothing above them) and below 1 under the plants.
  const int* dim = all.sceneLight().dim;
  const float* b04 = all.sceneLightValues().data() + 4 * n;
  float lowest = 1.0f;
  for (size_t i = 0; i < n; ++i) lowest = std::min(lowest, b04[i]);
  EXPECT_NEAR(b04[size_t(dim[0]) * (size_t(dim[1] - 1) + size_t(dim[1]) * size_t(dim[2] / 2)) + size_t(dim[0] / 2)], 1.0f, 0.05f);
  EXPECT_LT(lowest, 0.95f);
  // info reports the base count.
  const auto infoOf = [&](const std::string& file) {
    FILE* p = popen((std::string(CANOPY_BINARY_DIR) + "/bin/canopy-octreepack info '" + file + "' 2>/dev/null").c_str(), "r");
    std::string text;
    char buf[512];
    while (p && std::fgets(buf, sizeof buf, p)) text += buf;
    if (p) pclose(p);
    return text;
  };
  EXPECT_NE(infoOf(out).find("19 bases (B00 ambient, B01..B18 sun)"), std::string::npos) << infoOf(out);
  EXPECT_NE(infoOf(named).find("1 base (B00"), std::string::npos) << infoOf(named);
  // A scene lighting file without all 19 bases, or with a base on another lattice, is refused
  // (exit 3, nothing written), unless one grid is named.
  auto lattice = [](const char* name, double cell, int edge) {
    auto g = openvdb::FloatGrid::create(0.0f);
    g->setName(name);
    for (int k = 0; k < edge; ++k)
      for (int j = 0; j < edge; ++j)
        for (int i = 0; i < edge; ++i) g->tree().setValue(openvdb::Coord(i, j, k), 0.5f);
    g->setTransform(openvdb::math::Transform::createLinearTransform(cell));
    return openvdb::GridBase::Ptr(g);
  };
  openvdb::GridPtrVec partial, mixed;
  for (int b = 0; b < 19; ++b) {
    char name[8];
    std::snprintf(name, sizeof name, "B%02d", b);
    if (b != 7) partial.push_back(lattice(name, 1.0, 3));
    mixed.push_back(lattice(name, b == 11 ? 2.0 : 1.0, 3));
  }
  canopy::vdbio::writeVdb(dir + "/partial.scenelight.vdb", partial);
  canopy::vdbio::writeVdb(dir + "/mixed.scenelight.vdb", mixed);
  const std::string bad = dir + "/bad-scene-light.canopy";
  for (const char* file : {"partial", "mixed"}) {
    std::remove(bad.c_str());
    EXPECT_EQ(run("--scene '" + dir + "/lit.scene.json' --scene-light '" + dir + "/" + file + ".scenelight.vdb' -o '" + bad + "'"), 3) << file;
    EXPECT_FALSE(exists(bad)) << file;
  }
  EXPECT_EQ(run("--scene '" + dir + "/lit.scene.json' --scene-light '" + dir + "/partial.scenelight.vdb' --scene-light-grid B00 -o '" + bad + "'"), 0);
  EXPECT_EQ(CanopyFile::open(bad).sceneLightBases(), 1u);
  EXPECT_THROW(op::readSceneLightVdb(dir + "/partial.scenelight.vdb", ""), canopy::Error);
  try {
    op::readSceneLightVdb(dir + "/mixed.scenelight.vdb", "");
    ADD_FAILURE() << "a base on another lattice was accepted";
  } catch (const canopy::Error& e) {
    EXPECT_NE(std::string(e.what()).find("'B11' is not on B00's lattice"), std::string::npos) << e.what();
  }
}

TEST(OctreepackCli, NonFiniteDensityIsRejected) {
  op::ModelSource s = syntheticPlant(16, 0, "nan", 0);
  s.cells[3].density = std::numeric_limits<float>::quiet_NaN();
  const std::string dir = tmpDir();
  writeSourceVdb(dir + "/nan.density.vdb", s);
  std::remove((dir + "/nan.canopy").c_str());
  EXPECT_EQ(run("'" + dir + "/nan.density.vdb' -o '" + dir + "/nan.canopy'"), 3);
  EXPECT_FALSE(exists(dir + "/nan.canopy"));
}

// The density lattice's one rule (formats/density_lattice.h), also canopy-lbsolve's: a density is a
// biomass fraction in [0, 1]; above 1 the file is refused (before 2026-12 octreepack packed it).
TEST(OctreepackCli, DensityAboveOneIsRejected) {
  op::ModelSource s = syntheticPlant(16, 0, "big", 0);
  s.cells[3].density = 1.5f;
  const std::string dir = tmpDir();
  writeSourceVdb(dir + "/big.density.vdb", s);
  std::remove((dir + "/big.canopy").c_str());
  EXPECT_EQ(run("'" + dir + "/big.density.vdb' -o '" + dir + "/big.canopy'"), 3);
  EXPECT_FALSE(exists(dir + "/big.canopy"));
  try {
    op::readDensityVdb(dir + "/big.density.vdb", "big");
    ADD_FAILURE() << "density 1.5 accepted";
  } catch (const canopy::Error& e) {
    EXPECT_NE(std::string(e.what()).find("exceeds 1"), std::string::npos) << e.what();
  }
}

// The forest path: pipelines/scatter.py -> scene JSON -> canopy-octreepack --scene -> verify.
TEST(OctreepackCli, ScatteredForestOf400InstancesPacks) {
  const std::string dir = tmpDir();
  writeSourceVdb(dir + "/fa.density.vdb", syntheticPlant(24, 0, "fa", 0));
  writeSourceVdb(dir + "/fb.density.vdb", syntheticPlant(16, 0, "fb", 0));
  const std::string scatter = "python3 '" + std::string(CANOPY_SOURCE_DIR) + "/pipelines/scatter.py' --count 400 --seed 5 --radius 30 --model fa='" +
                              dir + "/fa.density.vdb' --model fb='" + dir + "/fb.density.vdb' -o ";
  ASSERT_EQ(std::system((scatter + "'" + dir + "/forest.scene.json' 2>/dev/null").c_str()), 0);
  ASSERT_EQ(std::system((scatter + "'" + dir + "/forest2.scene.json' 2>/dev/null").c_str()), 0);
  EXPECT_EQ(bytesOf(dir + "/forest.scene.json"), bytesOf(dir + "/forest2.scene.json"));  // deterministic
  EXPECT_EQ(run("--scene '" + dir + "/forest.scene.json' -o '" + dir + "/forest.canopy'"), 0);
  EXPECT_EQ(run("verify '" + dir + "/forest.canopy'"), 0);
  CanopyFile f = CanopyFile::open(dir + "/forest.canopy");
  EXPECT_EQ(f.instanceCount(), 400u);
  EXPECT_EQ(f.modelCount(), 2u);
  uint32_t perModel[2] = {0, 0};
  for (uint32_t i = 0; i < f.instanceCount(); ++i) {
    const auto& in = f.instance(i);
    ++perModel[in.model];
    const float x = in.modelToWorld[3], z = in.modelToWorld[11];
    ASSERT_LE(x * x + z * z, 30.0f * 30.0f + 1e-3f);
    const float s = in.modelToWorld[5];  // uniform scale (the yaw keeps the y axis)
    ASSERT_NEAR(in.modelToWorld[0] * in.modelToWorld[0] + in.modelToWorld[2] * in.modelToWorld[2], s * s, 1e-4f);
  }
  EXPECT_GT(perModel[0], 150u);
  EXPECT_GT(perModel[1], 150u);
}

// ---- lighting -------------------------------------------------------------------------------------
namespace {
// A fully occupied cube (every block present at every level, random densities: no constant nodes).
op::ModelSource denseCube(int edge) {
  op::ModelSource s;
  s.name = "cube";
  for (int a = 0; a < 3; ++a) s.latticeMin[a] = -2, s.latticeMax[a] = edge - 3;
  for (int k = 0; k < edge; ++k)
    for (int j = 0; j < edge; ++j)
      for (int i = 0; i < edge; ++i) {
        const uint32_t h = op::testing::mix32(uint32_t(i + 97 * j + 9973 * k));
        s.cells.push_back({{i - 2, j - 2, k - 2}, 0.1f + 0.8f * op::testing::unit(h), 0.0f, {0.2f, 0.5f, 0.1f}});
      }
  return s;
}
}  // namespace

// The tolerance of a light item's sample against reference RGB `ref`: the shared exponent's half
// unit, at most 1/511 of the largest channel (canopy/rgb9e5.h), plus the averaging's rounding.
double lightTolerance(const double ref[3]) {
  return std::max({std::abs(ref[0]), std::abs(ref[1]), std::abs(ref[2])}) / 511.0 + 1e-5;
}

// Light levels are the Haar averages of the source lighting: a light voxel of level d (2^(depth-d+1)
// cells wide) holds the mean of the source over its cells (within lightTolerance).
TEST(OctreepackLight, LightLevelsAreBoxFiltersOfTheSourceLighting) {
  const op::ModelSource src = denseCube(32);
  const op::BuiltModel m = op::buildOctree(src, "cube", op::testing::analyticLight);
  canopy::CanopyWriteInput in;
  in.models.push_back({m.record, &m.tiles, &m.bricks, &m.light});
  in.instances.push_back(canopy::CanopyInstance{});
  const std::vector<unsigned char> bytes = canopy::writeCanopyBytes(std::move(in));
  CanopyFile f = CanopyFile::fromMemory(bytes.data(), bytes.size(), "cube.canopy");
  const canopy::CanopyModel& M = f.model(0);
  ASSERT_EQ(M.depth, 2u);
  ASSERT_EQ(M.lightCount, M.brickCount);
  std::mt19937 rng(5);
  float tmp[canopy::kCanopyLightChannels];
  for (uint32_t level = 0; level <= M.depth; ++level) {
    const int cellsPerVoxel = 2 << (M.depth - level);
    const int voxels = 32 / cellsPerVoxel;  // light voxels per axis over the occupied cube
    for (int n = 0; n < 40; ++n) {
      const int g[3] = {int(rng() % uint32_t(voxels)), int(rng() % uint32_t(voxels)), int(rng() % uint32_t(voxels))};
      const uint32_t base = rng() % canopy::kCanopyLightBases;
      double ref[3] = {0, 0, 0};
      const int c = cellsPerVoxel;
      for (int z = 0; z < c; ++z)
        for (int y = 0; y < c; ++y)
          for (int x = 0; x < c; ++x) {
            op::testing::analyticLight(-2 + g[0] * c + x, -2 + g[1] * c + y, -2 + g[2] * c + z, tmp);
            for (int ch = 0; ch < 3; ++ch) ref[ch] += tmp[3 * base + ch];
          }
      const float u[3] = {(float(g[0]) + 0.5f) * float(c) / float(M.rootCells), (float(g[1]) + 0.5f) * float(c) / float(M.rootCells),
                          (float(g[2]) + 0.5f) * float(c) / float(M.rootCells)};
      const canopy::CanopyLookup r = f.descend(0, u[0], u[1], u[2], level);
      ASSERT_EQ(r.level, level);
      ASSERT_NE(r.node.brick, canopy::kCanopyNone);
      const auto page = f.readPage(canopy::canopyLightPage(M, r.node.brick, f.header().lightItemsPerPage));
      float rgb[3];
      canopy::canopySampleLight(canopy::canopyLightInPage(page.data(), r.node.brick % f.header().lightItemsPerPage), base, r.local[0],
                                r.local[1], r.local[2], rgb);
      for (double& v : ref) v /= double(c * c * c);
      for (int ch = 0; ch < 3; ++ch) ASSERT_NEAR(rgb[ch], ref[ch], lightTolerance(ref)) << "level " << level << " base " << base;
    }
  }
}

// An lbsolve-style light VDB (19 Vec3 grids B00..B18) packs through the CLI; samples at light
// voxel centres of the finest level equal the 2x2x2 mean of the grids' values.
TEST(OctreepackLight, LbsolveLightVdbPacksThroughTheCli) {
  const std::string dir = tmpDir();
  const op::ModelSource src = syntheticPlant(16, 0, "litcli", 0);
  writeSourceVdb(dir + "/litcli.density.vdb", src);
  writeLightVdb(dir + "/litcli.light.vdb", 16);
  float tmp[canopy::kCanopyLightChannels];
  const std::string out = dir + "/litcli.canopy";
  ASSERT_EQ(run("'" + dir + "/litcli.density.vdb' '" + dir + "/litcli.light.vdb' -o '" + out + "'"), 0);
  ASSERT_EQ(run("verify '" + out + "'"), 0);
  CanopyFile f = CanopyFile::open(out);
  const canopy::CanopyModel& M = f.model(0);
  ASSERT_TRUE(M.flags & canopy::kCanopyModelHasLight);
  ASSERT_EQ(M.lightCount, M.brickCount);
  ASSERT_EQ(M.depth, 1u);
  size_t checked = 0;
  for (int z = 0; z < 8; ++z)
    for (int y = 0; y < 8; ++y)
      for (int x = 0; x < 8; ++x) {  // finest light voxels (2 cells) over the 16^3 lattice
        const float u[3] = {(2.0f * float(x) + 1.0f) / 16.0f, (2.0f * float(y) + 1.0f) / 16.0f, (2.0f * float(z) + 1.0f) / 16.0f};
        const canopy::CanopyLookup r = f.descend(0, u[0], u[1], u[2], M.depth);
        if (r.level != M.depth || r.node.brick == canopy::kCanopyNone) continue;
        double ref[3] = {0, 0, 0};
        for (int s = 0; s < 8; ++s) {
          op::testing::analyticLight(2 * x + (s & 1), 2 * y + ((s >> 1) & 1), 2 * z + (s >> 2), tmp);
          for (int ch = 0; ch < 3; ++ch) ref[ch] += tmp[3 * 4 + ch] / 8.0;
        }
        const auto page = f.readPage(canopy::canopyLightPage(M, r.node.brick, f.header().lightItemsPerPage));
        float rgb[3];
        canopy::canopySampleLight(canopy::canopyLightInPage(page.data(), r.node.brick % f.header().lightItemsPerPage), 4, r.local[0],
                                  r.local[1], r.local[2], rgb);
        for (int ch = 0; ch < 3; ++ch) ASSERT_NEAR(rgb[ch], ref[ch], lightTolerance(ref));
        ++checked;
      }
  EXPECT_GT(checked, 50u);
}

// The mark of lbsolve's scattered-only sun bases (canopy_direct_beam = false on B01..B18) becomes
// the model flag kCanopyModelScatteredSun (format 1.1), shown by info; without the mark the file
// stays 1.0 and info says "total"; bases that disagree are refused with no output.
// A detail lattice (2x finer than its 16-cell light lattice) packs with lbsolve-style light on its
// light lattice: a 2.0 file whose model has one detail level, light items for the light levels,
// and info showing both lattices. Light whose lattice bounds or box differ, or that carries no
// lattice metadata, is refused (exit 3, nothing written).
TEST(OctreepackDetail, DetailLatticePacksWithItsLightLatticesLight) {
  const std::string dir = tmpDir();
  op::ModelSource fine = op::testing::syntheticPlant(32, 0, "leafy", 0);
  fine.detailLevels = 1;
  op::testing::writeSourceVdb(dir + "/leafy.detail.vdb", fine);
  // light lattice: cell c centred at the detail index point 2c + 0.5 (shift: its box moved)
  auto writeLight = [&](const std::string& path, int edge, double shift, bool meta) {
    std::array<double, 12> L{};
    for (int r = 0; r < 3; ++r) {
      const double* D = &fine.indexToModel[size_t(r * 4)];
      for (int c = 0; c < 3; ++c) L[size_t(r * 4 + c)] = 2.0 * D[c];
      L[size_t(r * 4 + 3)] = D[0] * 0.5 + D[1] * 0.5 + D[2] * 0.5 + D[3] + shift;
    }
    writeLightVdb(path, edge, 0, meta ? &L : nullptr);
  };
  writeLight(dir + "/leafy.light.vdb", 16, 0.0, true);
  const std::string out = dir + "/leafy-detail.canopy";
  std::remove(out.c_str());
  ASSERT_EQ(run("'" + dir + "/leafy.detail.vdb' '" + dir + "/leafy.light.vdb' --pages raw -o '" + out + "'"), 0);
  const canopy::CanopyFile f = canopy::CanopyFile::open(out);
  EXPECT_EQ(f.header().major, 4);  // detail levels (2.0) and light items (4.0), raw pages
  const canopy::CanopyModel& M = f.model(0);
  EXPECT_EQ(M.detailLevels, 1u);
  EXPECT_EQ(M.latticeMax[0], 31);
  EXPECT_GT(M.lightCount, 0u);
  EXPECT_LT(M.lightCount, M.brickCount);
  const op::BuiltModel built = op::buildOctree(fine, "leafy", op::testing::analyticLight);
  EXPECT_EQ(M.lightCount, built.record.lightCount);
  // info: both lattices
  const std::string cmd = std::string(CANOPY_BINARY_DIR) + "/bin/canopy-octreepack info '" + out + "' --json";
  FILE* p = popen(cmd.c_str(), "r");
  ASSERT_NE(p, nullptr);
  std::string text;
  char buf[4096];
  for (size_t n; (n = fread(buf, 1, sizeof buf, p)) > 0;) text.append(buf, n);
  EXPECT_EQ(pclose(p), 0);
  const nlohmann::json info = nlohmann::json::parse(text);
  EXPECT_EQ(info["models"][0]["detail_levels"], 1);
  EXPECT_EQ(info["models"][0]["light_lattice_max"][0], 15);
  EXPECT_EQ(info["models"][0]["lattice_max"][0], 31);
  bool sparseIndex = false;  // every section is named
  for (const auto& s : info["sections"]) {
    EXPECT_NE(s["name"], "unknown");
    sparseIndex = sparseIndex || s["name"] == "sparse_index";
  }
  EXPECT_TRUE(sparseIndex);
  // refused: another lattice, another box, no lattice metadata
  writeLight(dir + "/bounds.light.vdb", 15, 0.0, true);
  writeLight(dir + "/shifted.light.vdb", 16, 0.01, true);
  writeLight(dir + "/nometa.light.vdb", 16, 0.0, false);
  for (const char* bad : {"bounds", "shifted", "nometa"}) {
    const std::string o = dir + "/" + bad + ".canopy";
    std::remove(o.c_str());
    EXPECT_EQ(run("'" + dir + "/leafy.detail.vdb' '" + dir + "/" + bad + ".light.vdb' -o '" + o + "'"), 3) << bad;
    EXPECT_FALSE(exists(o)) << bad;
  }
}

TEST(OctreepackLight, ScatteredSunBasesAreFlagged) {
  const std::string dir = tmpDir();
  writeSourceVdb(dir + "/sunflag.density.vdb", syntheticPlant(16, 0, "sunflag", 0));
  const std::string density = "'" + dir + "/sunflag.density.vdb' ";
  for (uint32_t scattered : {18u, 0u}) {
    const std::string light = dir + "/sunflag" + std::to_string(scattered) + ".light.vdb";
    const std::string out = dir + "/sunflag" + std::to_string(scattered) + ".canopy";
    writeLightVdb(light, 16, scattered);
    ASSERT_EQ(run(density + "'" + light + "' --pages raw -o '" + out + "'"), 0);
    ASSERT_EQ(run("verify '" + out + "'"), 0);
    CanopyFile f = CanopyFile::open(out);
    EXPECT_EQ(bool(f.model(0).flags & canopy::kCanopyModelScatteredSun), scattered == 18);
    EXPECT_EQ(f.header().major, 4);  // light items, raw pages; the flag needs 1.1 or later
    const nlohmann::json info = op::canopyInfo(f);
    EXPECT_EQ(info["models"][0]["sun_bases"], scattered == 18 ? "scattered" : "total");
  }
  writeLightVdb(dir + "/sunflag-mixed.light.vdb", 16, 7);
  const std::string mixed = dir + "/sunflag-mixed.canopy";
  EXPECT_EQ(run(density + "'" + dir + "/sunflag-mixed.light.vdb' -o '" + mixed + "'"), 3);
  EXPECT_FALSE(std::filesystem::exists(mixed));
  // Packed density-only, the flag does not survive (it describes light items).
  EXPECT_EQ(run(density + "'" + dir + "/sunflag18.light.vdb' --ignore-light -o '" + dir + "/sunflag-dark.canopy'"), 0);
  EXPECT_FALSE(CanopyFile::open(dir + "/sunflag-dark.canopy").model(0).flags & canopy::kCanopyModelScatteredSun);
}

#include "formats/chaar.h"
#include "tests/haar/synthetic_light.h"

// .chaar lighting packed through the CLI (a 20^3 smooth light field, fp16, threshold 0.01; the
// lattice is the density's): the .chaar's bricks re-paged as Haar light, whose samples equal the
// chaar sampler's bit for bit, at every lattice cell and at random points in between; and light
// items on every level whose voxels are the box filter of the sampler's values at the lattice
// cells (within lightTolerance). --no-haar-light packs the items alone.
TEST(OctreepackLight, ChaarLightingEqualsTheDecoder) {
  namespace ht = canopy::haar::testing;
  const int n = 20;
  const canopy::haar::LatticeGeom g = ht::makeGeom(n, n, n, -2, -2, -2);
  std::vector<canopy::haar::DenseLight> lights;
  for (uint32_t b = 0; b < canopy::kCanopyLightBases; ++b) lights.push_back(ht::smoothLight(g, b));
  canopy::haar::ChaarData chaar = ht::encodeLights(g, lights, 0.01f, -1.0f, canopy::haar::Precision::Fp16);
  const canopy::haar::ChaarView view = chaar.view();
  const std::string dir = tmpDir();
  canopy::haar::writeChaar(dir + "/haarlit.light.chaar", chaar);
  const op::ModelSource src = denseCube(n);  // lattice (-2..17)^3, like g
  writeSourceVdb(dir + "/haarlit.density.vdb", src);
  const std::string out = dir + "/haarlit.canopy";
  ASSERT_EQ(run("'" + dir + "/haarlit.density.vdb' '" + dir + "/haarlit.light.chaar' --pages raw -o '" + out + "'"), 0);
  ASSERT_EQ(run("verify '" + out + "'"), 0);
  CanopyFile f = CanopyFile::open(out);
  const canopy::CanopyModel& M = f.model(0);
  ASSERT_TRUE(M.flags & canopy::kCanopyModelHaarLight);
  ASSERT_EQ(M.depth, 2u);
  EXPECT_EQ(M.lightCount, M.brickCount);
  EXPECT_EQ(M.haarItemCount, chaar.header.slotCount);
  const nlohmann::json info = op::canopyInfo(f);  // what `canopy-octreepack info --json` prints
  EXPECT_EQ(info["format_version"], "4.0");
  EXPECT_EQ(info["light_items"], "rgb9e5");
  EXPECT_EQ(info["models"][0]["haar_light"], true);
  EXPECT_EQ(info["models"][0]["haar_items"], chaar.header.slotCount);
  EXPECT_EQ(info["models"][0]["haar_precision"], "fp16");
  EXPECT_EQ(info["models"][0]["haar_pages"], M.haarPageCount);
  PackedSampler S(f);
  // Finest level: bit for bit.
  for (int k = -2; k < n - 2; ++k)
    for (int j = -2; j < n - 2; ++j)
      for (int i = -2; i < n - 2; ++i)
        for (uint32_t base = 0; base < canopy::kCanopyLightBases; ++base) {
          const canopy::haar::Rgb want = canopy::haar::chaarSample(view, int(base), float(i), float(j), float(k));
          const canopy::haar::Rgb got = S.sampleHaar(0, base, float(i), float(j), float(k));
          ASSERT_EQ(std::memcmp(&want, &got, sizeof want), 0) << "cell " << i << "," << j << "," << k << " base " << base;
        }
  std::mt19937 rng(9);
  std::uniform_real_distribution<float> U(-3.0f, float(n) - 1.0f);
  for (int t = 0; t < 20000; ++t) {
    const float p[3] = {U(rng), U(rng), U(rng)};
    const uint32_t base = uint32_t(t) % canopy::kCanopyLightBases;
    const canopy::haar::Rgb want = canopy::haar::chaarSample(view, int(base), p[0], p[1], p[2]);
    const canopy::haar::Rgb got = S.sampleHaar(0, base, p[0], p[1], p[2]);
    ASSERT_EQ(std::memcmp(&want, &got, sizeof want), 0) << "point " << p[0] << "," << p[1] << "," << p[2] << " base " << base;
  }
  // Every level's light items: box filters of the sampler's cell values.
  auto decoded = [&](uint32_t base, int i, int j, int k, int ch) {
    if (i > src.latticeMax[0] || j > src.latticeMax[1] || k > src.latticeMax[2]) return 0.0f;
    const canopy::haar::Rgb v = canopy::haar::chaarSample(view, int(base), float(i), float(j), float(k));
    return ch == 0 ? v.r : (ch == 1 ? v.g : v.b);
  };
  size_t checked = 0;
  for (uint32_t level = 0; level <= M.depth; ++level) {
    const int c = 2 << (M.depth - level);  // cells per light voxel
    for (int z = 0; z * c < n; ++z)
      for (int y = 0; y * c < n; ++y)
        for (int x = 0; x * c < n; ++x) {
          if ((x + 1) * c > n || (y + 1) * c > n || (z + 1) * c > n) continue;  // fully inside the lattice
          const float u[3] = {(float(x) + 0.5f) * float(c) / float(M.rootCells), (float(y) + 0.5f) * float(c) / float(M.rootCells),
                              (float(z) + 0.5f) * float(c) / float(M.rootCells)};
          const canopy::CanopyLookup r = f.descend(0, u[0], u[1], u[2], level);
          ASSERT_EQ(r.level, level);
          ASSERT_LT(r.node.brick, M.lightCount);
          const auto& page = S.pageData(canopy::canopyLightPage(M, r.node.brick, f.header().lightItemsPerPage));
          const uint32_t base = uint32_t(x + 3 * y + 5 * z) % canopy::kCanopyLightBases;
          float rgb[3];
          canopy::canopySampleLight(canopy::canopyLightInPage(page.data(), r.node.brick % f.header().lightItemsPerPage), base,
                                    r.local[0], r.local[1], r.local[2], rgb);
          double ref[3] = {0, 0, 0};
          for (int ch = 0; ch < 3; ++ch) {
            for (int dz = 0; dz < c; ++dz)
              for (int dy = 0; dy < c; ++dy)
                for (int dx = 0; dx < c; ++dx) ref[ch] += decoded(base, -2 + x * c + dx, -2 + y * c + dy, -2 + z * c + dz, ch);
            ref[ch] = std::max(ref[ch] / double(c * c * c), 0.0);  // the items hold no negative light (the codec's ringing)
          }
          for (int ch = 0; ch < 3; ++ch) ASSERT_NEAR(rgb[ch], ref[ch], lightTolerance(ref)) << "level " << level << " base " << base;
          ++checked;
        }
  }
  EXPECT_GT(checked, 8u);
  // Without the Haar bricks: the same items, no Haar pages.
  const std::string itemsOnly = dir + "/haarlit.items.canopy";
  ASSERT_EQ(run("'" + dir + "/haarlit.density.vdb' '" + dir + "/haarlit.light.chaar' --no-haar-light --pages raw -o '" + itemsOnly + "'"), 0);
  CanopyFile items = CanopyFile::open(itemsOnly);
  EXPECT_FALSE(items.model(0).flags & canopy::kCanopyModelHaarLight);
  EXPECT_EQ(items.model(0).lightCount, M.lightCount);
  EXPECT_TRUE(items.haarIndex().empty());
  EXPECT_GT(M.haarPageCount, 0u);
  EXPECT_EQ(f.header().fileBytes - items.header().fileBytes - uint64_t(M.haarPageCount) * f.header().pageBytes,
            f.header().residentBytes - items.header().residentBytes)
      << "the Haar pages and the HaarIndex (resident) are the difference";
}

#ifdef CANOPY_HAS_CUDA
#include "canopy/device.h"
#include "tests/octreepack/sample_cuda.h"
#endif

// The GPU path runs the same CANOPY_HD descent and brick sampling as the CPU reference: on a GPU
// host every sample must agree (same float operations; FMA contraction may differ: 1e-5).
TEST(OctreepackSample, cuda_MatchesCpuReference) {
#ifndef CANOPY_HAS_CUDA
  GTEST_SKIP() << "CPU-only build";
#else
  if (canopy::cudaDeviceCount() == 0) GTEST_SKIP() << "no CUDA device";
  CanopyFile f = CanopyFile::open(plantFile());
  PackedSampler S(f);
  std::mt19937 rng(11);
  std::uniform_real_distribution<float> U(0.0f, 1.0f);
  std::vector<float> pts(3 * 50000);
  for (float& p : pts) p = U(rng);
  for (uint32_t level : {0u, 1u, 2u, 3u}) {
    const std::vector<CanopySample> gpu = op::testing::sampleOnCuda(f, 0, pts, level);
    ASSERT_EQ(gpu.size(), pts.size() / 3);
    for (size_t i = 0; i < gpu.size(); ++i) {
      const CanopySample c = S.sampleUnit(0, &pts[3 * i], level);
      ASSERT_NEAR(gpu[i].density, c.density, 1e-5f) << "level " << level << " point " << i;
      for (int a = 0; a < 3; ++a) ASSERT_NEAR(gpu[i].albedo[a], c.albedo[a], 1e-5f);
      ASSERT_NEAR(gpu[i].wood, c.wood, 1e-5f);
    }
  }
  // Lighting on the device (shared-exponent decode + trilinear) vs the host, on a lit dense cube.
  const op::BuiltModel m = op::buildOctree(denseCube(32), "cube", op::testing::analyticLight);
  canopy::CanopyWriteInput in;
  in.models.push_back({m.record, &m.tiles, &m.bricks, &m.light});
  const std::vector<unsigned char> bytes = canopy::writeCanopyBytes(std::move(in));
  CanopyFile lit = CanopyFile::fromMemory(bytes.data(), bytes.size(), "cube.canopy");
  std::vector<float> rgb;
  op::testing::sampleOnCuda(lit, 0, pts, 2, &rgb, 9);
  for (size_t i = 0; i < pts.size() / 3; i += 7) {
    const canopy::CanopyLookup r = lit.descend(0, pts[3 * i], pts[3 * i + 1], pts[3 * i + 2], 2);
    if (r.node.brick == canopy::kCanopyNone) continue;
    const auto page = lit.readPage(canopy::canopyLightPage(lit.model(0), r.node.brick, lit.header().lightItemsPerPage));
    float ref[3];
    canopy::canopySampleLight(canopy::canopyLightInPage(page.data(), r.node.brick % lit.header().lightItemsPerPage), 9, r.local[0],
                              r.local[1], r.local[2], ref);
    for (int ch = 0; ch < 3; ++ch) ASSERT_NEAR(rgb[3 * i + ch], ref[ch], 1e-5f);
  }
#endif
}

