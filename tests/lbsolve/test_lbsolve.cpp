// canopy::lbsolve() and the canopy-lbsolve CLI on small lattices (CPU path): output layout and
// metadata, sun mode (linearity against the bases), scene mode, bad inputs (clear error, exit
// code, no output), `info`, determinism.
#include <gtest/gtest.h>
#include <sys/wait.h>

#include <algorithm>
#include <cmath>
#include <fstream>
#include <sstream>

#include "canopy/errors.h"
#include "canopy/lattice_dirs.h"
#include "canopy/sun_lookup.h"
#include "fixtures.h"
#include "formats/lattice_vdb.h"
#include "lattice_io.h"
#include "beam.h"
#include "lbsolve.h"

using namespace canopy;
using lattice::kQ;

namespace {

const std::string kTool = std::string(CANOPY_BINARY_DIR) + "/bin/canopy-lbsolve";

struct RunResult {
  int code = -1;
  std::string out;
};

// Runs a shell command line; stdout captured, stderr to the test log.
RunResult run(const std::string& cmd) {
  RunResult r;
  FILE* p = popen(cmd.c_str(), "r");
  if (!p) return r;
  char buf[4096];
  size_t n;
  while ((n = fread(buf, 1, sizeof buf, p)) > 0) r.out.append(buf, n);
  const int status = pclose(p);
  r.code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  return r;
}

std::string slurp(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::ostringstream s;
  s << in.rdbuf();
  return s.str();
}

LbsolveOptions quickOptions(const std::string& in, const std::string& out, int iterations = 12) {
  LbsolveOptions o;
  o.input = in;
  o.output = out;
  o.iterations = iterations;
  o.tolerance = 0.f;
  return o;
}

// Expects lbsolve(o) to throw canopy::Error with `code` and a message containing `what`, and no
// output file afterwards.
void expectFailure(const LbsolveOptions& o, ExitCode code, const std::string& what) {
  try {
    lbsolve(o);
    ADD_FAILURE() << "no error for " << what;
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), code) << e.what();
    EXPECT_NE(std::string(e.what()).find(what), std::string::npos) << e.what();
  }
  EXPECT_FALSE(fixtures::exists(o.output)) << o.output;
}

}  // namespace

TEST(Lbsolve, WritesNineteenBasesWithLatticeAndConvergenceMetadata) {
  const std::string dir = fixtures::scratch("bases");
  const fixtures::Plant plant = fixtures::makePlant(12);
  fixtures::writePlant(dir + "/p.vdb", plant);
  const LbsolveReport rep = lbsolve(quickOptions(dir + "/p.vdb", dir + "/p.light.vdb"));
  EXPECT_EQ(rep.solves.size(), 57u);
  EXPECT_EQ(rep.nodeUpdates, 57 * 12 * 12 * 12 * 12);

  const auto f = vdbio::readVdb(dir + "/p.light.vdb");
  const auto stored = lb::storedNodes({12, 12, 12}, plant.density);
  EXPECT_EQ(rep.storedNodes, int64_t(stored.size()));
  // The same lattice straight through the solver: the file must hold exactly these values.
  const lb::DenseLattice dense = fixtures::denseOf(12, 12, 12, plant.density, plant.wood);
  std::vector<lb::SolveSpec> specs;
  const lb::LightParams p;
  for (int b = 0; b < kQ; ++b)
    for (int c = 0; c < 3; ++c) {
      lb::SolveSpec s;
      s.omega = lb::makeOmegaSet(p.sigmaA[c], p.sigmaS[c], p.g[c], p.gWood, p.sigma);
      for (int m = 0; m < kQ; ++m) s.boundary[m] = (b == 0 || m == b) ? 1.f : 0.f;
      s.maxIterations = 12;
      specs.push_back(s);
    }
  auto direct = lb::runSolves(dense, specs, Device());
  // The sun bases are stored without their direct beam (beam.h): B_j - U_j, clamped at 0.
  for (size_t k = 3; k < specs.size(); ++k) {
    const std::vector<float> beam = lb::directBeam(dense, specs[k].omega, int(k / 3), 12);
    for (size_t i = 0; i < beam.size(); ++i) direct[k].values[i] = std::max(0.f, direct[k].values[i] - beam[i]);
  }
  EXPECT_EQ(rep.sunBases, "scattered");
  EXPECT_EQ(f.meta->metaValue<std::string>("canopy_sun_terms"), "scattered");
  for (int b = 0; b < kQ; ++b) {
    auto g = f.require<openvdb::Vec3SGrid>(lattice::baseName(b));
    EXPECT_EQ(g->activeVoxelCount(), stored.size());
    const auto meta = vdbio::readLatticeMeta(*g, "out");
    EXPECT_EQ(meta.min, openvdb::Coord(0));
    EXPECT_EQ(meta.max, openvdb::Coord(11));
    EXPECT_NE(meta.source.find("p.vdb xxh64:"), std::string::npos);
    auto d = g->getMetadata<openvdb::Vec3IMetadata>("canopy_direction");
    ASSERT_TRUE(d);
    EXPECT_EQ(d->value(), openvdb::Vec3i(lattice::dir(b, 0), lattice::dir(b, 1), lattice::dir(b, 2)));
    EXPECT_EQ(g->metaValue<openvdb::Vec3i>("canopy_iterations"), openvdb::Vec3i(12));
    EXPECT_TRUE(g->getMetadata<openvdb::Vec3SMetadata>("canopy_sigma_a"));
    EXPECT_EQ(g->metaValue<bool>("canopy_direct_beam"), b == 0) << b;
    auto acc = g->getConstAccessor();
    for (int64_t k : stored) {
      const openvdb::Vec3s v = acc.getValue(lb::nodeCoord(dense.dims, openvdb::Coord(0), k));
      for (int c = 0; c < 3; ++c) ASSERT_EQ(v[c], direct[size_t(3 * b + c)].values[size_t(k)]);
    }
  }
  auto sa = f.meta->metaValue<openvdb::Vec3s>("canopy_sigma_a");
  EXPECT_FLOAT_EQ(sa[0], 0.109f);
  EXPECT_FLOAT_EQ(f.meta->metaValue<openvdb::Vec3s>("canopy_g")[2], float(-0.02 / 0.06));
  // the medium it was lit for: canopy-play's default sigma, the Beer-Lambert collision
  EXPECT_FLOAT_EQ(f.meta->metaValue<float>("canopy_sigma"), 4.0f);
  EXPECT_EQ(f.meta->metaValue<std::string>("canopy_collision"), "beer-lambert");
  const auto conv = nlohmann::json::parse(f.meta->metaValue<std::string>("canopy_convergence"));
  EXPECT_EQ(conv.size(), 57u);
  EXPECT_EQ(f.meta->metaValue<std::string>("canopy_kind"), "bases");
  // info agrees.
  const LightFileInfo info = inspectLightFile(dir + "/p.light.vdb");
  EXPECT_EQ(info.kind, "bases");
  EXPECT_EQ(info.grids.size(), 19u);
}

// The solve is linear in the boundary values, so the static sun solution must equal the weighted
// sum of its three bases plus ambient x B_0 (tolerance: float rounding, 1e-5 of the maximum).
TEST(Lbsolve, SunSolutionIsTheWeightedSumOfItsBases) {
  const std::string dir = fixtures::scratch("sun");
  fixtures::writePlant(dir + "/p.vdb", fixtures::makePlant(12, 3));
  // The static sun solution holds all of the light, so it is the sum of the total bases (beam
  // included: --sun-bases total), not of the default scattered-only ones.
  LbsolveOptions total = quickOptions(dir + "/p.vdb", dir + "/bases.vdb", 20);
  total.scatteredSunBases = false;
  EXPECT_EQ(lbsolve(total).sunBases, "total");
  LbsolveOptions o = quickOptions(dir + "/p.vdb", dir + "/sun.vdb", 20);
  o.sun = std::array<float, 3>{0.3f, -1.0f, 0.45f};
  o.ambient = 0.25f;
  const LbsolveReport rep = lbsolve(o);
  EXPECT_EQ(rep.mode, "sun");
  EXPECT_EQ(rep.solves.size(), 3u);
  sun::Weights w;
  ASSERT_TRUE(sun::lookup(0.3f, -1.0f, 0.45f, w));
  EXPECT_GT(std::min({w.weight[0], w.weight[1], w.weight[2]}), 0.f);  // a face interior: 3 bases
  const auto bases = vdbio::readVdb(dir + "/bases.vdb");
  const auto sunFile = vdbio::readVdb(dir + "/sun.vdb");
  auto light = sunFile.require<openvdb::Vec3SGrid>("light");
  EXPECT_TRUE(light->metaValue<bool>("canopy_direct_beam"));
  EXPECT_EQ(bases.meta->metaValue<std::string>("canopy_sun_terms"), "total");
  for (int b = 0; b < kQ; ++b)
    EXPECT_TRUE(bases.require<openvdb::Vec3SGrid>(lattice::baseName(b))->metaValue<bool>("canopy_direct_beam")) << b;
  EXPECT_EQ(light->metaValue<openvdb::Vec3i>("canopy_sun_bases"), openvdb::Vec3i(w.base[0], w.base[1], w.base[2]));
  auto b0 = bases.require<openvdb::Vec3SGrid>("B00")->getConstAccessor();
  openvdb::Vec3SGrid::ConstAccessor bk[3] = {
      bases.require<openvdb::Vec3SGrid>(lattice::baseName(w.base[0]))->getConstAccessor(),
      bases.require<openvdb::Vec3SGrid>(lattice::baseName(w.base[1]))->getConstAccessor(),
      bases.require<openvdb::Vec3SGrid>(lattice::baseName(w.base[2]))->getConstAccessor()};
  int64_t count = 0;
  for (auto it = light->cbeginValueOn(); it; ++it, ++count) {
    openvdb::Vec3s want = b0.getValue(it.getCoord()) * 0.25f;
    for (int k = 0; k < 3; ++k) want += bk[k].getValue(it.getCoord()) * w.weight[k];
    for (int c = 0; c < 3; ++c) ASSERT_NEAR((*it)[c], want[c], 1e-5f * 19.f) << it.getCoord();
  }
  EXPECT_GT(count, 100);
  EXPECT_EQ(inspectLightFile(dir + "/sun.vdb").kind, "sun");
}

TEST(Lbsolve, WoodThresholdFlagChangesWhichNodesAreWood) {
  const std::string dir = fixtures::scratch("wood");
  fixtures::Plant p = fixtures::makePlant(10);
  for (auto& w : p.wood) w = p.density[&w - p.wood.data()] > 0 ? 0.3f : 0.f;
  fixtures::writePlant(dir + "/p.vdb", p);
  LbsolveOptions o = quickOptions(dir + "/p.vdb", dir + "/a.vdb", 10);
  lbsolve(o);
  o.output = dir + "/b.vdb";
  o.woodThreshold = 0.25;
  lbsolve(o);
  EXPECT_NE(slurp(dir + "/a.vdb"), slurp(dir + "/b.vdb"));
  const auto b = vdbio::readVdb(dir + "/b.vdb");
  EXPECT_FLOAT_EQ(b.meta->metaValue<float>("canopy_wood_threshold"), 0.25f);
}

TEST(Lbsolve, BadInputsGetAClearErrorAndNoOutput) {
  const std::string dir = fixtures::scratch("bad");
  const int n = 8;
  std::vector<float> d(size_t(n) * n * n, 0.f), w = d;
  d[(size_t(4) * n + 4) * n + 4] = 0.5f;
  auto write = [&](const std::string& name, const std::vector<float>& density, bool withWood = true) {
    fixtures::writeLattice(dir + "/" + name, n, n, n, density, w, 0.1, withWood);
    return dir + "/" + name;
  };
  const std::string good = write("good.vdb", d);

  std::ofstream(dir + "/text.vdb") << "this is not a VDB file\n";
  expectFailure(quickOptions(dir + "/text.vdb", dir + "/o1.vdb"), ExitCode::InvalidInput, "not an OpenVDB file");
  expectFailure(quickOptions(dir + "/missing.vdb", dir + "/o2.vdb"), ExitCode::Io, "missing.vdb");
  {
    // A VDB with a `density` grid but no lattice metadata.
    vdbio::initialize();
    auto g = openvdb::FloatGrid::create(0.f);
    g->setName("density");
    g->tree().setValue(openvdb::Coord(1), 0.5f);
    auto g2 = openvdb::FloatGrid::create(0.f);
    g2->setName("wood");
    vdbio::writeVdb(dir + "/plain.vdb", {g, g2});
  }
  expectFailure(quickOptions(dir + "/plain.vdb", dir + "/o3.vdb"), ExitCode::InvalidInput, "not a Canopy lattice");
  expectFailure(quickOptions(write("nowood.vdb", d, false), dir + "/o4.vdb"), ExitCode::InvalidInput,
                "no grid named 'wood'");
  auto nanD = d;
  nanD[(size_t(3) * n + 3) * n + 3] = std::nanf("");
  expectFailure(quickOptions(write("nan.vdb", nanD), dir + "/o5.vdb"), ExitCode::InvalidInput, "density is NaN at (3,3,3)");
  auto negD = d;
  negD[(size_t(2) * n + 3) * n + 5] = -0.25f;
  expectFailure(quickOptions(write("neg.vdb", negD), dir + "/o6.vdb"), ExitCode::InvalidInput,
                "negative density -0.25 at (5,3,2)");
  auto bigD = d;
  bigD[(size_t(2) * n + 2) * n + 2] = 1.5f;
  expectFailure(quickOptions(write("big.vdb", bigD), dir + "/o7.vdb"), ExitCode::InvalidInput, "exceeds 1");
  expectFailure(quickOptions(good, dir + "/no/such/dir/o8.vdb"), ExitCode::Io, "o8.vdb");
  {
    // A truncated lattice file.
    const std::string bytes = slurp(good);
    std::ofstream(dir + "/trunc.vdb", std::ios::binary).write(bytes.data(), std::streamsize(bytes.size() / 2));
  }
  expectFailure(quickOptions(dir + "/trunc.vdb", dir + "/o9.vdb"), ExitCode::InvalidInput, "trunc.vdb");
  {
    LbsolveOptions o = quickOptions(good, dir + "/o10.vdb");
    o.paramsFile = dir + "/params.json";
    std::ofstream(o.paramsFile) << R"({"sigma_a": [0.1, 0.1, 2.0]})";
    expectFailure(o, ExitCode::InvalidInput, "sigma_a must lie in [0, 1]");
  }
  {
    LbsolveOptions o = quickOptions(good, dir + "/o11.vdb");
    o.tolerance = 0.f;
    o.iterations = 0;
    expectFailure(o, ExitCode::Usage, "--tolerance 0 needs --iterations");
  }
  // A lattice too small to have an interior.
  {
    std::vector<float> tiny(2 * 2 * 2, 0.f);
    fixtures::writeLattice(dir + "/tiny.vdb", 2, 2, 2, tiny, tiny);
    expectFailure(quickOptions(dir + "/tiny.vdb", dir + "/o12.vdb"), ExitCode::InvalidInput, "too small");
  }
  // The good file works.
  lbsolve(quickOptions(good, dir + "/ok.vdb", 4));
  EXPECT_TRUE(fixtures::exists(dir + "/ok.vdb"));
}

TEST(Lbsolve, SceneModeBuildsTheCoarseLatticeFromInstances) {
  const std::string dir = fixtures::scratch("scene");
  const fixtures::Plant plant = fixtures::makePlant(12);
  fixtures::writePlant(dir + "/tree.vdb", plant);  // 12 x 0.05 m = 0.6 m cube
  std::ofstream(dir + "/s.scene.json") << R"({"canopy_scene": 1,
    "models": [{"name": "tree", "density": "tree.vdb"}],
    "instances": [{"model": 0, "matrix": [1,0,0,0, 0,1,0,0, 0,0,1,0, 0,0,0,1]},
                  {"model": 0, "matrix": [0,0,1,1.5, 0,1,0,0, -1,0,0,0, 0,0,0,1]}]})";
  LbsolveOptions o;
  o.scene = dir + "/s.scene.json";
  o.output = dir + "/scene.vdb";
  o.sceneResolution = 10;
  const LbsolveReport rep = lbsolve(o);
  EXPECT_EQ(rep.mode, "scene");
  EXPECT_EQ(rep.solves.size(), 19u);
  const LightFileInfo info = inspectLightFile(o.output);
  EXPECT_EQ(info.kind, "scene");
  const auto f = vdbio::readVdb(o.output);
  auto density = f.require<openvdb::FloatGrid>("density");
  // Mass is conserved: sum of coarse density x cell volume = 2 x the plant's biomass volume.
  const double h = f.meta->metaValue<double>("canopy_scene_cell");
  double coarse = 0, fine = 0;
  for (auto it = density->cbeginValueOn(); it; ++it) coarse += *it * h * h * h;
  for (float v : plant.density) fine += v * 0.05 * 0.05 * 0.05;
  EXPECT_NEAR(coarse, 2 * fine, 1e-6 * fine);
  // World box x [-0.025, 2.075], y [-0.025, 0.575], z [-0.575, 0.575]; h = 2.1 / 10: interior
  // 10 x 3 x 6 cells plus the boundary layer.
  EXPECT_NEAR(h, 0.21, 1e-9);
  auto down = f.require<openvdb::FloatGrid>("B04");  // light travelling -y
  const auto meta = vdbio::readLatticeMeta(*down, o.output);
  EXPECT_EQ(meta.max, openvdb::Coord(11, 4, 7));
  // Normalised: the boundary holds 1, and light from above is darker under the crowns than on top.
  auto acc = down->getConstAccessor();
  EXPECT_FLOAT_EQ(acc.getValue(openvdb::Coord(0, 4, 0)), 1.f);
  double top = 0, bottom = 0;
  for (int z = 1; z <= 6; ++z)
    for (int x = 1; x <= 10; ++x) {
      top += acc.getValue(openvdb::Coord(x, 3, z));
      bottom += acc.getValue(openvdb::Coord(x, 1, z));
    }
  EXPECT_LT(bottom, top);
  EXPECT_GT(top / 60, 0.5);
  EXPECT_EQ(f.require<openvdb::FloatGrid>("B00")->getConstAccessor().getValue(openvdb::Coord(0)), 1.f);
}

// The scene lattice's normalisation: every base is 1 at an interior node that nothing occludes,
// B00 included (there f_0 is zeroed at every collision and only the 18 moving populations arrive:
// B00 = 18 before the normalisation, not the boundary's 19). Such a node is one whose 18 upstream
// lines to the boundary (and itself) hold no coarse matter: nothing can be scattered into it either.
TEST(Lbsolve, SceneLightIsOneWhereNothingOccludesAnInteriorNode) {
  const std::string dir = fixtures::scratch("scene_unoccluded");
  fixtures::writePlant(dir + "/tree.vdb", fixtures::makePlant(12));  // a 0.6 m cube
  std::ofstream(dir + "/s.scene.json") << R"({"canopy_scene": 1,
    "models": [{"name": "tree", "density": "tree.vdb"}],
    "instances": [{"model": 0, "matrix": [1,0,0,0, 0,1,0,0, 0,0,1,0, 0,0,0,1]},
                  {"model": 0, "matrix": [1,0,0,3, 0,1,0,2, 0,0,1,3, 0,0,0,1]}]})";
  LbsolveOptions o;
  o.scene = dir + "/s.scene.json";
  o.output = dir + "/scene.vdb";
  o.sceneResolution = 12;
  lbsolve(o);
  const auto f = vdbio::readVdb(o.output);
  auto density = f.require<openvdb::FloatGrid>("density")->getConstAccessor();
  const auto meta = vdbio::readLatticeMeta(*f.require<openvdb::FloatGrid>("B00"), o.output);
  const openvdb::Coord hi = meta.max;
  auto interior = [&](const openvdb::Coord& c) {
    return c.x() > 0 && c.y() > 0 && c.z() > 0 && c.x() < hi.x() && c.y() < hi.y() && c.z() < hi.z();
  };
  // upstream along -c_m from c to the boundary: all empty?
  auto clear = [&](const openvdb::Coord& c) {
    if (density.getValue(c) != 0.f) return false;
    for (int m = 1; m < kQ; ++m) {
      openvdb::Coord q = c;
      while (interior(q)) {
        if (density.getValue(q) != 0.f) return false;
        q -= openvdb::Coord(lattice::dir(m, 0), lattice::dir(m, 1), lattice::dir(m, 2));
      }
    }
    return true;
  };
  std::vector<openvdb::FloatGrid::ConstAccessor> bases;
  for (int b = 0; b < kQ; ++b) bases.push_back(f.require<openvdb::FloatGrid>(lattice::baseName(b))->getConstAccessor());
  int checked = 0, occludedBelowOne = 0;
  for (int z = 1; z < hi.z(); ++z)
    for (int y = 1; y < hi.y(); ++y)
      for (int x = 1; x < hi.x(); ++x) {
        const openvdb::Coord c(x, y, z);
        if (clear(c)) {
          ++checked;
          for (int b = 0; b < kQ; ++b) EXPECT_NEAR(bases[size_t(b)].getValue(c), 1.f, 1e-6f) << lattice::baseName(b) << " at " << c;
        } else if (bases[0].getValue(c) < 1.f) {
          ++occludedBelowOne;
        }
      }
  EXPECT_GT(checked, 10);          // the scene has open space
  EXPECT_GT(occludedBelowOne, 10);  // and shade: B00 < 1 behind the trees
  EXPECT_FLOAT_EQ(bases[0].getValue(openvdb::Coord(0)), 1.f);  // the boundary layer (19 / 19)
  // the coarse lattice's collision is the linear one, which has no sigma
  EXPECT_EQ(f.meta->metaValue<std::string>("canopy_collision"), "linear");
  EXPECT_FALSE(nlohmann::json::parse(f.meta->metaValue<std::string>("canopy_params")).contains("sigma"));
  EXPECT_EQ(f.meta->getMetadata<openvdb::FloatMetadata>("canopy_sigma"), nullptr);
}

// ---- the CLI, run as a separate process -------------------------------------------------------

TEST(Cli, EndToEndWithJsonReportAndInfo) {
  const std::string dir = fixtures::scratch("cli");
  fixtures::writePlant(dir + "/p.vdb", fixtures::makePlant(10));
  const RunResult r = run(kTool + " " + dir + "/p.vdb -o " + dir + "/p.light.vdb --device cpu --iterations 6 --tolerance 0 --json -q");
  ASSERT_EQ(r.code, 0) << r.out;
  const auto j = nlohmann::json::parse(r.out);
  EXPECT_EQ(j["exit_code"], 0);
  EXPECT_EQ(j["mode"], "bases");
  ASSERT_EQ(j["solves"].size(), 57u);
  for (const auto& s : j["solves"]) EXPECT_EQ(s["iterations"], 6);
  EXPECT_EQ(j["lattice"], nlohmann::json({10, 10, 10}));

  const RunResult info = run(kTool + " info " + dir + "/p.light.vdb --json");
  ASSERT_EQ(info.code, 0) << info.out;
  const auto ij = nlohmann::json::parse(info.out);
  EXPECT_EQ(ij["kind"], "bases");
  EXPECT_EQ(ij["grids"].size(), 19u);
  EXPECT_EQ(ij["lattice_max"], nlohmann::json({9, 9, 9}));
  EXPECT_EQ(ij["metadata"]["canopy_convergence"].size(), 57u);
  const RunResult text = run(kTool + " info " + dir + "/p.light.vdb");
  EXPECT_EQ(text.code, 0);
  EXPECT_NE(text.out.find("B18"), std::string::npos);

  // info on something that is not a light file fails.
  EXPECT_EQ(run(kTool + " info " + dir + "/p.vdb 2>/dev/null").code, int(ExitCode::InvalidInput));
  EXPECT_EQ(run(kTool + " info " + dir + "/nothing.vdb 2>/dev/null").code, int(ExitCode::Io));

  // --sun writes one `light` grid.
  const RunResult s = run(kTool + " " + dir + "/p.vdb -o " + dir + "/sun.vdb --sun 0,-1,0.2 --iterations 6 --tolerance 0 -q");
  ASSERT_EQ(s.code, 0);
  EXPECT_EQ(run(kTool + " info " + dir + "/sun.vdb --json -q").code, 0);
}

TEST(Cli, SameInputsGiveTheSameBytes) {
  const std::string dir = fixtures::scratch("determinism");
  fixtures::writePlant(dir + "/p.vdb", fixtures::makePlant(9));
  for (const char* out : {"a.vdb", "b.vdb"})
    ASSERT_EQ(run(kTool + " " + dir + "/p.vdb -o " + dir + "/" + out + " --device cpu -q").code, 0);
  const std::string a = slurp(dir + "/a.vdb"), b = slurp(dir + "/b.vdb");
  EXPECT_GT(a.size(), 1000u);
  EXPECT_EQ(a, b);
}

TEST(Cli, ExitCodesAndNoOutputOnErrors) {
  const std::string dir = fixtures::scratch("cli_errors");
  fixtures::writePlant(dir + "/p.vdb", fixtures::makePlant(8));
  const std::string out = dir + "/o.vdb";
  auto code = [&](const std::string& args) { return run(kTool + " " + args + " 2>/dev/null").code; };
  EXPECT_EQ(code(dir + "/p.vdb"), int(ExitCode::Usage));  // no -o
  EXPECT_EQ(code(dir + "/p.vdb -o " + out + " --tolerance 0"), int(ExitCode::Usage));
  EXPECT_EQ(code(dir + "/p.vdb -o " + out + " --sun 0,0,0"), int(ExitCode::Usage));
  EXPECT_EQ(code(dir + "/p.vdb -o " + out + " --sun 1,2"), int(ExitCode::Usage));
  EXPECT_EQ(code(dir + "/p.vdb -o " + out + " --device gpu"), int(ExitCode::Usage));
  EXPECT_EQ(code(dir + "/p.vdb -o " + out + " --cuda-scheme bogus"), int(ExitCode::Usage));
  EXPECT_EQ(code(dir + "/p.vdb -o " + out + " --cuda-scheme push-fused"), int(ExitCode::Usage));  // not a scheme (measured, then removed)
  EXPECT_EQ(code(dir + "/p.vdb -o " + out + " --solves-per-gpu 0"), int(ExitCode::Usage));
  EXPECT_EQ(code(dir + "/p.vdb -o " + out + " --solves-per-gpu 65"), int(ExitCode::Usage));
  // An out-of-range --wood-threshold is a usage error like every other bad option value (it was
  // 3 for 2 and 1 for nan); the same value in a --params file is invalid input.
  std::ofstream(dir + "/good.json") << R"({"wood_threshold": 0.4})";
  std::ofstream(dir + "/wood2.json") << R"({"wood_threshold": 2})";
  for (const std::string& bad : std::vector<std::string>{"2", "nan", "-0.5", "2 --params " + dir + "/good.json"}) {
    const RunResult r = run(kTool + " " + dir + "/p.vdb -o " + out + " --device cpu --wood-threshold " + bad + " 2>&1");
    EXPECT_EQ(r.code, int(ExitCode::Usage)) << bad << "\n" << r.out;
    EXPECT_NE(r.out.find("--wood-threshold must lie in [0, 1]"), std::string::npos) << r.out;
  }
  const RunResult wood = run(kTool + " " + dir + "/p.vdb -o " + out + " --device cpu --params " + dir + "/wood2.json 2>&1");
  EXPECT_EQ(wood.code, int(ExitCode::InvalidInput)) << wood.out;
  EXPECT_NE(wood.out.find("wood2.json: wood_threshold must lie in [0, 1]"), std::string::npos) << wood.out;
  EXPECT_EQ(code(dir + "/none.vdb -o " + out), int(ExitCode::Io));
  EXPECT_EQ(code(dir + "/p.vdb -o " + dir + "/missing-dir/o.vdb"), int(ExitCode::Io));
  if (cudaDeviceCount() == 0) {
    EXPECT_EQ(code(dir + "/p.vdb -o " + out + " --device cuda"), int(ExitCode::Unsupported));
  }
  std::ofstream(dir + "/bad.json") << "{ not json";
  EXPECT_EQ(code(dir + "/p.vdb -o " + out + " --params " + dir + "/bad.json"), int(ExitCode::InvalidInput));
  EXPECT_FALSE(fixtures::exists(out));
  // The error is one line naming the file.
  const RunResult r = run(kTool + " " + dir + "/none.vdb -o " + out + " 2>&1");
  EXPECT_NE(r.out.find("canopy-lbsolve: error: "), std::string::npos);
  EXPECT_NE(r.out.find("none.vdb"), std::string::npos);
  EXPECT_EQ(std::count(r.out.begin(), r.out.end(), '\n'), 1) << r.out;
  EXPECT_EQ(run(kTool + " --help >/dev/null").code, 0);
  EXPECT_EQ(run(kTool + " --version >/dev/null").code, 0);
}
