// The density lattice file's one contract (formats/density_lattice.h), in one place: the writer and
// the reader round trip (the detail relation's too); every truncated prefix and flipped byte, a newer
// OpenVDB file version, every bad grid or value and every bad detail relation fails with a one-line
// canopy::Error naming the file, never a crash (this test compiles density_lattice.cpp and
// lattice_vdb.cpp itself, under ASan/UBSan). canopy-lbsolve, canopy-octreepack and canopy-voxelize
// info all read lattices through readDensityLattice, so their own tests only check how they report
// its errors.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>
#include <map>
#include <sstream>
#include <tuple>

#include "canopy/errors.h"
#include "formats/density_lattice.h"

namespace fs = std::filesystem;
using namespace canopy;
using vdbio::DensityCell;
using vdbio::DensityLatticeData;

namespace {

std::string scratch(const std::string& name) {
  const fs::path d = fs::path(CANOPY_BINARY_DIR) / "tests" / "formats" / "scratch" / name;
  fs::remove_all(d);
  fs::create_directories(d);
  return d.string();
}
std::string slurp(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::ostringstream s;
  s << in.rdbuf();
  return s.str();
}
void spit(const std::string& path, const std::string& bytes) {
  std::ofstream(path, std::ios::binary | std::ios::trunc).write(bytes.data(), std::streamsize(bytes.size()));
}

// A 10^3 lattice with a small plant in its interior (the boundary layer empty, as voxelize writes).
DensityLatticeData plant() {
  DensityLatticeData d;
  d.meta.min = openvdb::Coord(0);
  d.meta.max = openvdb::Coord(9);
  d.meta.source = "plant.glb xxh64:0123456789abcdef";
  d.transform = openvdb::math::Transform::createLinearTransform(0.05);
  d.transform->postTranslate(openvdb::Vec3d(-0.25, 0.0, -0.25));
  for (int z = 2; z < 8; ++z)
    for (int y = 1; y < 9; ++y)
      for (int x = 3; x < 7; ++x) {
        const float rho = float((x + 2 * y + 3 * z) % 8 + 1) / 8.f;  // 1/8 .. 1
        d.cells.push_back({{x, y, z}, rho, y < 4 ? 1.f : 0.f, {0.1f * x, 0.05f * y, 0.02f * z}});
      }
  d.fileMeta.insertMeta("canopy_tool", openvdb::StringMetadata("test"));
  d.fileMeta.insertMeta("canopy_mesh_index", openvdb::Int32Metadata(2));
  return d;
}

// The error readDensityLattice throws for `path` (code Ok and "" when it reads).
struct Outcome {
  ExitCode code = ExitCode::Ok;
  std::string what;
};
Outcome readOutcome(const std::string& path) {
  try {
    vdbio::readDensityLattice(path);
    return {};
  } catch (const Error& e) {
    return {e.code(), e.what()};
  }
}

// Writes `grids` (density, wood, albedo from plant() after `edit`) and expects InvalidInput whose
// one-line message names the file and contains `expected`.
void expectInvalid(const std::string& path, const openvdb::GridPtrVec& grids, const std::string& expected) {
  vdbio::writeVdb(path, grids);
  const Outcome o = readOutcome(path);
  EXPECT_EQ(o.code, ExitCode::InvalidInput) << expected;
  EXPECT_EQ(o.what.rfind(path + ": ", 0), 0u) << o.what;
  EXPECT_EQ(o.what.find('\n'), std::string::npos) << o.what;
  EXPECT_NE(o.what.find(expected), std::string::npos) << o.what;
}

openvdb::FloatGrid& floatGrid(const openvdb::GridPtrVec& g, size_t i) { return static_cast<openvdb::FloatGrid&>(*g[i]); }
openvdb::Vec3SGrid& albedoGrid(const openvdb::GridPtrVec& g) { return static_cast<openvdb::Vec3SGrid&>(*g[2]); }

}  // namespace

TEST(DensityLattice, WriterAndReaderRoundTrip) {
  const std::string dir = scratch("roundtrip");
  const DensityLatticeData in = plant();
  vdbio::writeDensityLattice(dir + "/a.vdb", in);
  vdbio::writeDensityLattice(dir + "/b.vdb", in);
  EXPECT_EQ(slurp(dir + "/a.vdb"), slurp(dir + "/b.vdb"));  // deterministic bytes

  const vdbio::DensityLattice L = vdbio::readDensityLattice(dir + "/a.vdb");
  EXPECT_EQ(L.meta.min, in.meta.min);
  EXPECT_EQ(L.meta.max, in.meta.max);
  EXPECT_EQ(L.meta.source, in.meta.source);
  EXPECT_EQ(*L.transform, *in.transform);
  ASSERT_EQ(L.cells.size(), in.cells.size());
  // The density grid's order is its tree's (z fastest within a leaf); compare as sets.
  auto key = [](const DensityCell& c) { return std::make_tuple(c.ijk[0], c.ijk[1], c.ijk[2]); };
  std::vector<DensityCell> a = in.cells, b = L.cells;
  auto byKey = [&](const DensityCell& x, const DensityCell& y) { return key(x) < key(y); };
  std::sort(a.begin(), a.end(), byKey);
  std::sort(b.begin(), b.end(), byKey);
  for (size_t i = 0; i < a.size(); ++i) {
    EXPECT_EQ(key(a[i]), key(b[i]));
    EXPECT_EQ(a[i].density, b[i].density);
    EXPECT_EQ(a[i].wood, b[i].wood);
    for (int c = 0; c < 3; ++c) EXPECT_EQ(a[i].albedo[c], b[i].albedo[c]);
  }
  EXPECT_EQ(L.fileMeta.metaValue<int32_t>("canopy_mesh_index"), 2);
  ASSERT_EQ(L.grids.size(), 3u);
  std::map<std::string, uint64_t> active;
  for (const auto& g : L.grids) active[g.name] = g.activeVoxels;
  EXPECT_EQ(active, (std::map<std::string, uint64_t>{{"albedo", in.cells.size()}, {"density", in.cells.size()},
                                                     {"wood", in.cells.size()}}));

  // The layout any OpenVDB client sees: a fog volume, the §0 metadata on every grid.
  const vdbio::VdbFile f = vdbio::readVdb(dir + "/a.vdb");
  EXPECT_EQ(f.require<openvdb::FloatGrid>("density")->getGridClass(), openvdb::GRID_FOG_VOLUME);
  for (const char* name : {"density", "wood", "albedo"}) {
    const openvdb::GridBase::Ptr g = f.find(name);
    ASSERT_TRUE(g) << name;
    EXPECT_TRUE(g->getMetadata<openvdb::StringMetadata>("canopy_version")) << name;
    EXPECT_EQ(vdbio::readLatticeMeta(*g, f.path).max, in.meta.max) << name;
  }
  EXPECT_EQ(f.find("albedo")->metaValue<std::string>("canopy_color_space"), "linear sRGB");

  const vdbio::DensityLatticeOrigin origin = vdbio::readDensityLatticeOrigin(dir + "/a.vdb");
  EXPECT_EQ(origin.source, in.meta.source);
  EXPECT_TRUE(origin.hasMeshIndex);
  EXPECT_EQ(origin.meshIndex, 2);
}

TEST(DensityLattice, DensityZeroIsNoCellAndActiveTilesAreExpanded) {
  const std::string dir = scratch("tiles");
  DensityLatticeData in = plant();
  in.cells.push_back({{1, 1, 1}, 0.f, 0.f, {0, 0, 0}});  // an active zero: no cell
  openvdb::GridPtrVec g = vdbio::densityLatticeGrids(in);
  floatGrid(g, 0).tree().setValueOn(openvdb::Coord(-50), 0.f);  // a zero outside the lattice is fine
  // An active 8^3 tile of density 0.25 inside a 40^3 lattice.
  for (auto& grid : g) {
    vdbio::LatticeMeta m = in.meta;
    m.max = openvdb::Coord(39);
    vdbio::stampGrid(*grid, m);
  }
  floatGrid(g, 0).tree().addTile(1, openvdb::Coord(16), 0.25f, true);
  vdbio::writeVdb(dir + "/t.vdb", g);
  const vdbio::DensityLattice L = vdbio::readDensityLattice(dir + "/t.vdb");
  EXPECT_EQ(L.cells.size(), in.cells.size() - 1 + 512);
  size_t tileCells = 0;
  for (const DensityCell& c : L.cells) tileCells += c.density == 0.25f && c.ijk[0] >= 16 && c.ijk[0] < 24 ? 1 : 0;
  EXPECT_EQ(tileCells, 512u);
}

TEST(DensityLattice, EveryTruncatedPrefixAndFlippedByteFailsCleanly) {
  const std::string dir = scratch("truncated");
  vdbio::writeDensityLattice(dir + "/good.vdb", plant());
  const std::string good = slurp(dir + "/good.vdb");
  ASSERT_EQ(readOutcome(dir + "/good.vdb").code, ExitCode::Ok);
  const std::string bad = dir + "/bad.vdb";
  // Every prefix through the header and the first grid's metadata, then every 61st byte; every
  // 97th byte flipped (the content checksum catches it).
  for (size_t n = 0; n < good.size(); n += (n < 1024 ? 1 : 61)) {
    spit(bad, good.substr(0, n));
    const Outcome o = readOutcome(bad);
    ASSERT_TRUE(o.code == ExitCode::InvalidInput || o.code == ExitCode::Io) << "prefix " << n << ": " << o.what;
    ASSERT_EQ(o.what.find('\n'), std::string::npos) << o.what;
  }
  for (size_t i = 0; i < good.size(); i += 97) {
    std::string flipped = good;
    flipped[i] = char(flipped[i] ^ 0x5a);
    spit(bad, flipped);
    ASSERT_EQ(readOutcome(bad).code, ExitCode::InvalidInput) << "byte " << i;
  }
  spit(bad, good + "trailing");
  EXPECT_EQ(readOutcome(bad).code, ExitCode::InvalidInput);
  EXPECT_EQ(readOutcome(dir + "/missing.vdb").code, ExitCode::Io);
}

TEST(DensityLattice, NewerOpenVdbFileVersionIsRefused) {
  const std::string dir = scratch("version");
  vdbio::writeDensityLattice(dir + "/good.vdb", plant());
  std::string bytes = slurp(dir + "/good.vdb");
  // Header: magic (8 bytes), then the file format version (u32). The UUID is re-derived, so only
  // the version can make the reader refuse it (OpenVDB itself would read on).
  uint32_t version = 0;
  std::memcpy(&version, &bytes[8], 4);
  EXPECT_EQ(version, openvdb::OPENVDB_FILE_VERSION);
  version += 100;
  std::memcpy(&bytes[8], &version, 4);
  ASSERT_TRUE(vdbio::rewriteUuid(bytes));
  spit(dir + "/newer.vdb", bytes);
  const Outcome o = readOutcome(dir + "/newer.vdb");
  EXPECT_EQ(o.code, ExitCode::InvalidInput) << o.what;
  EXPECT_EQ(o.what.rfind(dir + "/newer.vdb: ", 0), 0u) << o.what;
  EXPECT_EQ(o.what.find('\n'), std::string::npos) << o.what;
}

TEST(DensityLattice, DensityOutsideZeroOneAndBadValuesAreRefused) {
  const std::string dir = scratch("values");
  const openvdb::Coord c(4, 3, 2);
  auto withDensity = [&](float v) {
    openvdb::GridPtrVec g = vdbio::densityLatticeGrids(plant());
    floatGrid(g, 0).tree().setValue(c, v);
    return g;
  };
  expectInvalid(dir + "/big.vdb", withDensity(1.5f), "density 1.5 at (4,3,2) exceeds 1");
  expectInvalid(dir + "/neg.vdb", withDensity(-0.25f), "negative density -0.25 at (4,3,2)");
  expectInvalid(dir + "/nan.vdb", withDensity(std::nanf("")), "density is NaN at (4,3,2)");
  expectInvalid(dir + "/inf.vdb", withDensity(std::numeric_limits<float>::infinity()), "density is infinite at (4,3,2)");
  {
    openvdb::GridPtrVec g = withDensity(1.0f);  // exactly 1 is a full cell
    vdbio::writeVdb(dir + "/one.vdb", g);
    EXPECT_EQ(readOutcome(dir + "/one.vdb").code, ExitCode::Ok);
  }
  {
    openvdb::GridPtrVec g = vdbio::densityLatticeGrids(plant());
    floatGrid(g, 1).tree().setValue(c, 1.25f);
    expectInvalid(dir + "/wood.vdb", g, "wood fraction 1.25 at (4,3,2) is outside [0, 1]");
  }
  {
    openvdb::GridPtrVec g = vdbio::densityLatticeGrids(plant());
    floatGrid(g, 1).tree().setValue(c, std::nanf(""));
    expectInvalid(dir + "/woodnan.vdb", g, "wood fraction is not finite at (4,3,2)");
  }
  {
    openvdb::GridPtrVec g = vdbio::densityLatticeGrids(plant());
    albedoGrid(g).tree().setValue(c, openvdb::Vec3s(0.5f, std::numeric_limits<float>::infinity(), 0.5f));
    expectInvalid(dir + "/albedo.vdb", g, "albedo is not finite at (4,3,2)");
  }
  {
    openvdb::GridPtrVec g = vdbio::densityLatticeGrids(plant());
    floatGrid(g, 0).tree().setValue(openvdb::Coord(10, 3, 3), 0.5f);
    expectInvalid(dir + "/outside.vdb", g, "non-zero density at (10,3,3) outside the lattice (0,0,0)..(9,9,9)");
  }
}

TEST(DensityLattice, MissingOrMismatchedGridsAreRefused) {
  const std::string dir = scratch("grids");
  for (size_t drop : {0, 1, 2}) {
    openvdb::GridPtrVec g = vdbio::densityLatticeGrids(plant());
    const std::string name = g[drop]->getName();
    g.erase(g.begin() + long(drop));
    expectInvalid(dir + "/no" + name + ".vdb", g, "no grid named '" + name + "'");
  }
  {
    openvdb::GridPtrVec g = vdbio::densityLatticeGrids(plant());
    auto vec = openvdb::Vec3SGrid::create();
    vec->setName("wood");
    g[1] = vec;
    expectInvalid(dir + "/woodtype.vdb", g, "grid 'wood' has type Tree_vec3s");
  }
  {
    openvdb::GridPtrVec g = vdbio::densityLatticeGrids(plant());
    g[0]->removeMeta("canopy_lattice_min");
    expectInvalid(dir + "/nometa.vdb", g, "not a Canopy lattice");
  }
  {
    openvdb::GridPtrVec g = vdbio::densityLatticeGrids(plant());
    vdbio::LatticeMeta m = plant().meta;
    m.max = openvdb::Coord(10);
    vdbio::stampGrid(*g[2], m);
    expectInvalid(dir + "/bounds.vdb", g, "grid 'albedo' has a different lattice than 'density'");
  }
  {
    DensityLatticeData d = plant();
    openvdb::GridPtrVec g = vdbio::densityLatticeGrids(d);
    auto density = openvdb::FloatGrid::create(0.5f);  // background 0.5: every unset node would be half full
    density->setName("density");
    density->setTransform(d.transform->copy());
    density->tree().setValue(openvdb::Coord(4), 0.25f);
    vdbio::stampGrid(*density, d.meta);
    g[0] = density;
    expectInvalid(dir + "/background.vdb", g, "grid 'density' has background 0.5, expected 0");
  }
}

// ---- The detail relation (canopy-voxelize --detail) ----------------------------------------------

namespace {

// plant()'s 10^3 lattice as the detail lattice of a 5^3 light lattice (k = 2).
DensityLatticeData detailPlant(int factor = 2, openvdb::Coord lightMin = openvdb::Coord(0),
                               openvdb::Coord lightMax = openvdb::Coord(4)) {
  DensityLatticeData d = plant();
  d.detailFactor = factor;
  d.lightMin = lightMin;
  d.lightMax = lightMax;
  return d;
}

}  // namespace

TEST(DensityLattice, DetailRelationRoundTrip) {
  const std::string dir = scratch("detail");
  vdbio::writeDensityLattice(dir + "/d.vdb", detailPlant());
  const vdbio::DensityLattice L = vdbio::readDensityLattice(dir + "/d.vdb");
  EXPECT_EQ(L.detailFactor, 2);
  EXPECT_EQ(L.lightMin, openvdb::Coord(0));
  EXPECT_EQ(L.lightMax, openvdb::Coord(4));
  EXPECT_EQ(L.cells.size(), plant().cells.size());
  // On the density grid only, as the int32 and vec3i any OpenVDB client reads.
  const vdbio::VdbFile f = vdbio::readVdb(dir + "/d.vdb");
  const openvdb::GridBase::Ptr density = f.find("density");
  EXPECT_EQ(density->metaValue<int32_t>(vdbio::kDetailFactorMeta), 2);
  EXPECT_EQ(density->metaValue<openvdb::Vec3i>(vdbio::kLightLatticeMaxMeta), openvdb::Vec3i(4, 4, 4));
  for (const char* name : {"wood", "albedo"}) EXPECT_FALSE(f.find(name)->getMetadata<openvdb::Int32Metadata>(vdbio::kDetailFactorMeta));

  // A lattice that is not a detail lattice: factor 1, no metadata; the bytes are those it always had.
  vdbio::writeDensityLattice(dir + "/plain.vdb", plant());
  const vdbio::DensityLattice P = vdbio::readDensityLattice(dir + "/plain.vdb");
  EXPECT_EQ(P.detailFactor, 1);
  EXPECT_FALSE(vdbio::readVdb(dir + "/plain.vdb").find("density")->getMetadata<openvdb::Int32Metadata>(vdbio::kDetailFactorMeta));
  DensityLatticeData one = plant();
  one.detailFactor = 1;
  one.lightMax = openvdb::Coord(7);  // ignored at factor 1
  vdbio::writeDensityLattice(dir + "/one.vdb", one);
  EXPECT_EQ(slurp(dir + "/one.vdb"), slurp(dir + "/plain.vdb"));

  // A lattice that does not start at 0: light cells [1, 3] x 2 = detail cells [2, 7].
  DensityLatticeData shifted = detailPlant(2, openvdb::Coord(1), openvdb::Coord(3));
  shifted.meta.min = openvdb::Coord(2);
  shifted.meta.max = openvdb::Coord(7);
  shifted.cells.erase(std::remove_if(shifted.cells.begin(), shifted.cells.end(),
                                     [](const DensityCell& c) {
                                       return *std::min_element(c.ijk, c.ijk + 3) < 2 || *std::max_element(c.ijk, c.ijk + 3) > 7;
                                     }),
                      shifted.cells.end());
  vdbio::writeDensityLattice(dir + "/shifted.vdb", shifted);
  const vdbio::DensityLattice S = vdbio::readDensityLattice(dir + "/shifted.vdb");
  EXPECT_EQ(S.lightMin, openvdb::Coord(1));
  EXPECT_EQ(S.lightMax, openvdb::Coord(3));
  // k = 16 over a 32^3 lattice.
  DensityLatticeData big = detailPlant(16, openvdb::Coord(0), openvdb::Coord(1));
  big.meta.max = openvdb::Coord(31);
  vdbio::writeDensityLattice(dir + "/k16.vdb", big);
  EXPECT_EQ(vdbio::readDensityLattice(dir + "/k16.vdb").detailFactor, 16);
}

TEST(DensityLattice, DetailRelationIsChecked) {
  const std::string dir = scratch("detailbad");
  auto grids = [](const DensityLatticeData& d) { return vdbio::densityLatticeGrids(d); };
  expectInvalid(dir + "/k3.vdb", grids(detailPlant(3)), "canopy_detail_factor is 3, expected 2, 4, 8 or 16");
  expectInvalid(dir + "/k32.vdb", grids(detailPlant(32)), "canopy_detail_factor is 32, expected 2, 4, 8 or 16");
  expectInvalid(dir + "/k0.vdb", grids(detailPlant(0)), "canopy_detail_factor is 0, expected 2, 4, 8 or 16");
  expectInvalid(dir + "/kneg.vdb", grids(detailPlant(-2)), "canopy_detail_factor is -2, expected 2, 4, 8 or 16");
  // The light lattice x k must be the lattice: one cell short, one cell off, the wrong factor.
  expectInvalid(dir + "/short.vdb", grids(detailPlant(2, openvdb::Coord(0), openvdb::Coord(3))),
                "its light lattice (0,0,0)..(3,3,3) x 2 is not its lattice (0,0,0)..(9,9,9)");
  expectInvalid(dir + "/off.vdb", grids(detailPlant(2, openvdb::Coord(1), openvdb::Coord(5))),
                "its light lattice (1,1,1)..(5,5,5) x 2 is not its lattice (0,0,0)..(9,9,9)");
  expectInvalid(dir + "/onlyx.vdb", grids(detailPlant(2, openvdb::Coord(0), openvdb::Coord(4, 4, 3))),
                "its light lattice (0,0,0)..(4,4,3) x 2 is not its lattice");
  expectInvalid(dir + "/k4.vdb", grids(detailPlant(4)), "its light lattice (0,0,0)..(4,4,4) x 4 is not its lattice");
  expectInvalid(dir + "/inverted.vdb", grids(detailPlant(2, openvdb::Coord(4), openvdb::Coord(0))),
                "its light lattice (4,4,4)..(0,0,0) x 2");
  for (const char* name : {vdbio::kLightLatticeMinMeta, vdbio::kLightLatticeMaxMeta}) {
    openvdb::GridPtrVec g = grids(detailPlant());
    g[0]->removeMeta(name);
    expectInvalid(dir + "/no" + std::string(name) + ".vdb", g, "a detail lattice without canopy_light_lattice_min/");
  }
}
