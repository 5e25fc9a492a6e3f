// canopy-haar end to end: light VDB files in lbsolve's layout (built here with lattice_vdb.h),
// the library entry points, and the executable's command lines, exit codes and outputs.
#include <gtest/gtest.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>

#include <openvdb/tools/Dense.h>

#include "canopy/atomic_file.h"
#include "formats/lattice_vdb.h"
#include "haar.h"
#include "synthetic_light.h"

namespace fs = std::filesystem;
using namespace canopy::haar;
using namespace canopy::haar::testing;

namespace {

const std::string kTool = std::string(CANOPY_BINARY_DIR) + "/bin/canopy-haar";

// One scratch directory per test process, removed at exit.
struct ScratchDir {
  fs::path path;
  ScratchDir() : path(fs::temp_directory_path() / ("canopy_haar_" + std::to_string(getpid()))) {
    fs::create_directories(path);
  }
  ~ScratchDir() {
    std::error_code ec;
    fs::remove_all(path, ec);
  }
};
fs::path tempDir() {
  static ScratchDir d;
  return d.path;
}

std::string slurp(const fs::path& p) {
  std::ifstream f(p, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(f), {});
}

// Writes an lbsolve-style file: Vec3 grids B00.., lattice metadata, canopy_direction, 1 cm voxels.
// noBeam: bit b marks base b canopy_direct_beam = false (canopy-lbsolve marks the sun bases 1..18:
// kSunBases); 0: no such metadata at all (light files from before it).
constexpr uint32_t kSunBases = ((1u << 19) - 1) & ~1u;
void writeLightVdb(const std::string& path, const LatticeGeom& g, const std::vector<DenseLight>& lights,
                   uint32_t noBeam = 0) {
  canopy::vdbio::initialize();
  canopy::vdbio::LatticeMeta m;
  m.min = openvdb::Coord(g.min[0], g.min[1], g.min[2]);
  m.max = openvdb::Coord(g.max[0], g.max[1], g.max[2]);
  m.source = "synthetic";
  openvdb::GridPtrVec grids;
  auto xf = openvdb::math::Transform::createLinearTransform(0.01);
  xf->postTranslate(openvdb::Vec3d(-0.5, 0.0, -0.25));
  for (uint32_t b = 0; b < lights.size(); ++b) {
    auto grid = openvdb::Vec3SGrid::create(openvdb::Vec3s(0.0f));
    grid->setName(baseName(b));
    grid->setTransform(xf->copy());
    std::vector<float> copy = lights[b].rgb;
    openvdb::tools::Dense<openvdb::Vec3s, openvdb::tools::LayoutXYZ> dense(
        openvdb::CoordBBox(m.min, m.max), reinterpret_cast<openvdb::Vec3s*>(copy.data()));
    openvdb::tools::copyFromDense(dense, *grid, openvdb::Vec3s(0.0f), true);
    canopy::vdbio::stampGrid(*grid, m);
    const auto c = latticeDirection(b);
    grid->insertMeta("canopy_direction", openvdb::Vec3IMetadata(openvdb::Vec3i(c[0], c[1], c[2])));
    if (noBeam) grid->insertMeta("canopy_direct_beam", openvdb::BoolMetadata(!(noBeam >> b & 1u)));
    grids.push_back(grid);
  }
  canopy::vdbio::writeVdb(path, grids);
}

std::vector<DenseLight> smoothSet(const LatticeGeom& g, uint32_t n = 19) {
  std::vector<DenseLight> v;
  for (uint32_t b = 0; b < n; ++b) v.push_back(smoothLight(g, b, 1.0f + 0.1f * float(b)));
  return v;
}

// The shared fixture: a smooth 19-base light field on a 14x12x10 lattice.
const std::string& smoothFile() {
  static std::string path = [] {
    const LatticeGeom g = makeGeom(14, 12, 10, -3, 0, 2);
    const std::string p = (tempDir() / "smooth.light.vdb").string();
    writeLightVdb(p, g, smoothSet(g));
    return p;
  }();
  return path;
}

int run(const std::string& args, std::string* out = nullptr) {
  const std::string outFile = (tempDir() / "stdout.txt").string();
  const int rc = std::system((kTool + " " + args + " > " + outFile + " 2> " + (tempDir() / "stderr.txt").string()).c_str());
  if (out) *out = slurp(outFile);
  return WIFEXITED(rc) ? WEXITSTATUS(rc) : -1;
}
std::string lastStderr() { return slurp(tempDir() / "stderr.txt"); }

}  // namespace

TEST(HaarTool, CompressDecodeRoundTripMatchesReportedErrors) {
  for (Precision p : {Precision::Fp32, Precision::Quant}) {
  SCOPED_TRACE(precisionName(p));
  const std::string out = (tempDir() / "a.chaar").string(), dec = (tempDir() / "a.decoded.vdb").string();
  CompressOptions o;
  o.input = smoothFile();
  o.output = out;
  o.threshold = 0.01f;
  o.precision = p;
  const nlohmann::json rep = compressLight(o);
  ASSERT_EQ(rep["bases"].size(), 19u);
  decodeToVdb(out, dec);
  // Independent check: decoded VDB vs input VDB, cell by cell.
  const LightFieldPtr in = openLightField(o.input), back = openLightField(dec);
  EXPECT_EQ(lightGeom(*back).cells, lightGeom(*in).cells);
  double worst = 0;
  for (uint32_t b = 0; b < 19; ++b) {
    std::array<int32_t, 3> d1, d2;
    const DenseLight a = lightBase(*in, b, d1), c = lightBase(*back, b, d2);
    EXPECT_EQ(d1, d2);
    double m = 0, ss = 0;
    for (size_t i = 0; i < a.rgb.size(); ++i) {
      const double e = std::fabs(double(a.rgb[i]) - c.rgb[i]);
      m = std::max(m, e);
      ss += e * e;
    }
    const auto& rb = rep["bases"][b];
    EXPECT_LE(m, rb["max_error"].get<double>()) << b;  // cells are a subset of the stored texels
    EXPECT_NEAR(std::sqrt(ss / a.rgb.size()), rb["rms_error"].get<double>(), 1e-6) << b;
    worst = std::max(worst, m);
  }
  EXPECT_GT(worst, 0.0);  // the threshold did drop something
  EXPECT_GT(rep["overall"]["ratio_dense"].get<double>(), 1.0);
  EXPECT_EQ(rep["overall"]["bytes_file"].get<uint64_t>(), fs::file_size(out));
  // Transform and lattice survive.
  const ChaarData d = readChaar(out);
  EXPECT_NEAR(d.header.indexToModel[0], 0.01, 1e-12);
  EXPECT_NEAR(d.header.indexToModel[12], -0.5, 1e-12);
  EXPECT_EQ(d.header.latticeMin[0], -3);
  EXPECT_EQ(d.precision(), p);
  }
}

TEST(HaarTool, MaxErrorHoldsOnRandomAndSmoothFieldsInEveryPrecision) {
  const LatticeGeom g = makeGeom(11, 10, 9);
  std::vector<DenseLight> rnd;
  for (uint32_t b = 0; b < 19; ++b) rnd.push_back(randomLight(g, 100 + b, 0.5f + 0.1f * float(b)));
  const std::string rndFile = (tempDir() / "random.light.vdb").string();
  writeLightVdb(rndFile, g, rnd);
  for (const std::string& in : {smoothFile(), rndFile})
    for (Precision p : {Precision::Fp32, Precision::Fp16, Precision::Quant}) {
      CompressOptions o;
      o.input = in;
      o.output = (tempDir() / "me.chaar").string();
      o.maxError = 0.01f;
      o.precision = p;
      const nlohmann::json rep = compressLight(o);
      const ChaarData d = readChaar(o.output);
      const LightFieldPtr f = openLightField(in);
      std::vector<float> dense;
      for (uint32_t b = 0; b < d.baseCount(); ++b) {
        std::array<int32_t, 3> dir;
        const DenseLight a = lightBase(*f, b, dir);
        decodeBaseDense(d, b, dense);
        double m = 0;
        for (size_t i = 0; i < dense.size(); ++i) m = std::max(m, std::fabs(double(dense[i]) - a.rgb[i]));
        ASSERT_LE(m, 0.01) << in << " " << precisionName(p) << " " << baseName(b);
        ASSERT_LE(rep["bases"][b]["max_error"].get<double>(), 0.01);
      }
    }
}

TEST(HaarTool, CliCommandsReportsAndDeterministicBytes) {
  const std::string a = (tempDir() / "c1.chaar").string(), b = (tempDir() / "c2.chaar").string();
  std::string out;
  ASSERT_EQ(run(smoothFile() + " -o " + a + " --threshold 0.005 --precision fp16 --json", &out), 0) << lastStderr();
  const nlohmann::json rep = nlohmann::json::parse(out);
  EXPECT_EQ(rep["exit_code"], 0);
  EXPECT_EQ(rep["precision"], "fp16");
  for (const char* k : {"bytes_dense_fp32", "bytes_sparse", "bytes_file", "ratio_dense", "rms_error", "max_error", "psnr_db"})
    EXPECT_TRUE(rep["overall"].contains(k)) << k;
  EXPECT_NE(lastStderr().find("PSNR"), std::string::npos);  // human report on stderr
  ASSERT_EQ(run(smoothFile() + " -o " + b + " --threshold 0.005 --precision fp16 -q"), 0);
  EXPECT_EQ(slurp(a), slurp(b)) << "two runs must give identical bytes";

  ASSERT_EQ(run("info " + a + " --json", &out), 0) << lastStderr();
  const nlohmann::json info = nlohmann::json::parse(out);
  EXPECT_EQ(info["bases"].size(), 19u);
  EXPECT_EQ(info["precision"], "fp16");
  EXPECT_EQ(info["format_version"], "1.0");
  EXPECT_EQ(run("verify " + a), 0) << lastStderr();

  const std::string dec = (tempDir() / "c1.vdb").string();
  ASSERT_EQ(run("decode " + a + " -o " + dec), 0) << lastStderr();
  const LightFieldPtr f = openLightField(dec);
  EXPECT_EQ(lightBaseCount(*f), 19u);
  const std::string dec2 = (tempDir() / "c1b.vdb").string();
  ASSERT_EQ(run("decode " + a + " -o " + dec2), 0);
  EXPECT_EQ(slurp(dec), slurp(dec2));

  // --max-error from the command line, in the default precision (fp16), which keeps the bound and
  // is smaller than fp32 at the same bound.
  ASSERT_EQ(run(smoothFile() + " -o " + b + " --max-error 0.02 --json", &out), 0) << lastStderr();
  const nlohmann::json byDefault = nlohmann::json::parse(out);
  EXPECT_EQ(byDefault["precision"], "fp16");
  EXPECT_LE(byDefault["overall"]["max_error"].get<double>(), 0.02);
  const std::string b32 = (tempDir() / "c2_fp32.chaar").string();
  ASSERT_EQ(run(smoothFile() + " -o " + b32 + " --max-error 0.02 --precision fp32 --json", &out), 0) << lastStderr();
  EXPECT_LE(nlohmann::json::parse(out)["overall"]["max_error"].get<double>(), 0.02);
  EXPECT_LT(fs::file_size(b), fs::file_size(b32));
}

// info and verify print their report on stdout (redirectable), also under -q; logs stay on stderr.
// Before the fix both reports went to stderr through the log, so -q printed nothing at all.
TEST(HaarTool, InfoAndVerifyPrintTheirReportOnStdoutAlsoWhenQuiet) {
  const std::string a = (tempDir() / "report.chaar").string();
  ASSERT_EQ(run(smoothFile() + " -o " + a + " --threshold 0.005 -q"), 0) << lastStderr();
  for (const char* quiet : {"", " -q"}) {
    std::string out;
    ASSERT_EQ(run("info " + a + quiet, &out), 0) << lastStderr();
    EXPECT_EQ(out.rfind(a + ": .chaar 1.", 0), 0u) << out;
    EXPECT_NE(out.find("\n  B18 dir ("), std::string::npos) << out;  // one line per base
    EXPECT_EQ(std::count(out.begin(), out.end(), '\n'), 20) << out;
    EXPECT_EQ(lastStderr(), "");
    ASSERT_EQ(run("verify " + a + quiet, &out), 0) << lastStderr();
    EXPECT_EQ(out, a + ": OK (checksums, indices and 19 decoded bases)\n");
    EXPECT_EQ(lastStderr(), "");
  }
  std::string out;
  ASSERT_EQ(run("info " + a + " --json", &out), 0);
  EXPECT_EQ(nlohmann::json::parse(out)["bases"].size(), 19u);  // --json: only the object on stdout
}

// lbsolve's scattered-only sun bases keep their mark through canopy-haar: the .chaar's base flags
// (format 1.1), info's direct_beam, and decode's canopy_direct_beam metadata.
TEST(HaarTool, ScatteredSunBasesKeepTheirMarkThroughEncodeAndDecode) {
  const LatticeGeom g = makeGeom(14, 12, 10, -3, 0, 2);
  const std::string in = (tempDir() / "scattered.light.vdb").string();
  const std::string c = (tempDir() / "scattered.chaar").string(), dec = (tempDir() / "scattered.dec.vdb").string();
  writeLightVdb(in, g, smoothSet(g), kSunBases);
  ASSERT_EQ(run(in + " -o " + c + " --threshold 0.005 -q"), 0) << lastStderr();
  std::string out;
  ASSERT_EQ(run("info " + c + " --json", &out), 0) << lastStderr();
  const nlohmann::json info = nlohmann::json::parse(out);
  EXPECT_EQ(info["format_version"], "1.1");
  for (uint32_t b = 0; b < 19; ++b) EXPECT_EQ(info["bases"][b]["direct_beam"], b == 0) << b;
  ASSERT_EQ(run("decode " + c + " -o " + dec), 0) << lastStderr();
  const canopy::vdbio::VdbFile f = canopy::vdbio::readVdb(dec);
  for (uint32_t b = 0; b < 19; ++b)
    EXPECT_EQ(f.require<openvdb::Vec3SGrid>(baseName(b))->metaValue<bool>("canopy_direct_beam"), b == 0) << b;
  const LightFieldPtr lf = openLightField(dec);
  EXPECT_TRUE(lightBaseHasBeam(*lf, 0));
  EXPECT_FALSE(lightBaseHasBeam(*lf, 5));
  EXPECT_TRUE(lightBaseHasBeam(*openLightField(smoothFile()), 5));  // no metadata: beam included
  // A marked ambient base, or sun bases that disagree, are refused (exit 3) with no output.
  for (uint32_t bad : {kSunBases | 1u, kSunBases & ~(1u << 7)}) {
    const std::string badIn = (tempDir() / "badmark.light.vdb").string(), badOut = (tempDir() / "badmark.chaar").string();
    writeLightVdb(badIn, g, smoothSet(g), bad);
    EXPECT_EQ(run(badIn + " -o " + badOut + " -q"), 3) << bad;
    EXPECT_NE(lastStderr().find("canopy_direct_beam"), std::string::npos) << lastStderr();
    EXPECT_FALSE(std::filesystem::exists(badOut));
  }
}

TEST(HaarTool, CliRejectsBadInputsWithDocumentedExitCodes) {
  const fs::path d = tempDir();
  const std::string out = (d / "bad.chaar").string();
  fs::remove(out);
  EXPECT_EQ(run((d / "missing.vdb").string() + " -o " + out), 2);
  EXPECT_NE(lastStderr().find("missing.vdb"), std::string::npos) << lastStderr();
  std::ofstream((d / "notvdb.vdb").string()) << "hello";
  EXPECT_EQ(run((d / "notvdb.vdb").string() + " -o " + out), 3);
  EXPECT_EQ(run(smoothFile() + " -o " + out + " --threshold -1"), 1);
  EXPECT_EQ(run(smoothFile() + " -o " + out + " --threshold 0.1 --max-error 0.1"), 1);
  EXPECT_EQ(run(smoothFile() + " -o " + out + " --precision fp8"), 1);
  EXPECT_EQ(run(smoothFile()), 1);  // no -o
  EXPECT_EQ(run(smoothFile() + " -o /nonexistent-dir/x.chaar"), 2);
  EXPECT_EQ(run(smoothFile() + " -o " + out + " --max-error 0 --precision fp16"), 5);  // unattainable
  EXPECT_EQ(run(smoothFile() + " -o " + out + " --max-error 0 --precision quant"), 5);
  EXPECT_EQ(run(smoothFile() + " -o " + out + " --precision quant"), 1);  // quant needs a step
  EXPECT_NE(lastStderr().find("--precision quant needs --threshold"), std::string::npos) << lastStderr();
  EXPECT_EQ(run(smoothFile() + " -o " + out + " --precision quant --threshold 1e-9"), 5);  // levels overflow
  EXPECT_NE(lastStderr().find("more than 15 bits"), std::string::npos) << lastStderr();
  EXPECT_FALSE(fs::exists(out)) << "a failed run must leave no output";
  for (auto& e : fs::directory_iterator(d))
    EXPECT_EQ(e.path().filename().string().find(".canopy-tmp."), std::string::npos) << e.path();

  // A VDB whose grids are not Vec3 / lack B00 / carry NaN.
  canopy::vdbio::initialize();
  auto fg = openvdb::FloatGrid::create(0.0f);
  fg->setName("B00");
  canopy::vdbio::LatticeMeta m;
  m.max = openvdb::Coord(4);
  canopy::vdbio::stampGrid(*fg, m);
  canopy::vdbio::writeVdb((d / "float.vdb").string(), {fg});
  EXPECT_EQ(run((d / "float.vdb").string() + " -o " + out), 3);
  const LatticeGeom g = makeGeom(6, 6, 6);
  std::vector<DenseLight> nan = {smoothLight(g, 0)};
  nan[0].rgb[3 * 100] = NAN;
  writeLightVdb((d / "nan.vdb").string(), g, nan);
  EXPECT_EQ(run((d / "nan.vdb").string() + " -o " + out), 3);
  EXPECT_NE(lastStderr().find("non-finite"), std::string::npos) << lastStderr();
  EXPECT_FALSE(fs::exists(out));

  // Corrupt / truncated .chaar: info, verify and decode fail with 3 and name the file.
  const std::string good = (d / "good.chaar").string();
  ASSERT_EQ(run(smoothFile() + " -o " + good + " -q"), 0);
  std::string bytes = slurp(good);
  bytes[bytes.size() / 2] ^= 0x10;
  std::ofstream((d / "corrupt.chaar").string(), std::ios::binary) << bytes;
  for (const std::string cmd : {"verify", "info"}) {
    EXPECT_EQ(run(cmd + " " + (d / "corrupt.chaar").string()), 3) << cmd;
    EXPECT_NE(lastStderr().find("corrupt.chaar"), std::string::npos) << lastStderr();
  }
  EXPECT_EQ(run("decode " + (d / "corrupt.chaar").string() + " -o " + (d / "x.vdb").string()), 3);
  EXPECT_FALSE(fs::exists(d / "x.vdb"));
  std::ofstream((d / "short.chaar").string(), std::ios::binary) << bytes.substr(0, 100);
  EXPECT_EQ(run("verify " + (d / "short.chaar").string()), 3);
  EXPECT_EQ(run("verify " + (d / "none.chaar").string()), 2);
  EXPECT_EQ(run("bogus-subcommand -o " + out), 2);  // taken as a missing input file
}

TEST(HaarTool, SweepWritesTablePlotAndJson) {
  const std::string prefix = (tempDir() / "sweep").string();
  std::string out;
  ASSERT_EQ(run("sweep " + smoothFile() + " --thresholds 0,0.001,0.01,0.05 -o " + prefix + " --json", &out), 0)
      << lastStderr();
  const std::string csv = slurp(prefix + ".csv");
  EXPECT_EQ(csv.rfind("threshold,base,bytes,ratio_dense,ratio_sparse,max_error,rms_error,psnr_db\n", 0), 0u);
  size_t lines = 0;
  for (char c : csv) lines += c == '\n';
  EXPECT_EQ(lines, 1u + 4 * 20);  // header + 4 thresholds x (19 bases + all)
  const nlohmann::json j = nlohmann::json::parse(slurp(prefix + ".json"));
  ASSERT_EQ(j["rows"].size(), 80u);
  // The sweep's whole-file size equals a real compression at the same threshold.
  const std::string real = (tempDir() / "sweep_check.chaar").string();
  ASSERT_EQ(run(smoothFile() + " -o " + real + " --threshold 0.01 -q"), 0);
  for (const auto& r : j["rows"])
    if (r["base"] == "all" && std::fabs(r["threshold"].get<double>() - 0.01) < 1e-9) {
      EXPECT_EQ(r["bytes"].get<uint64_t>(), fs::file_size(real));
    }
  // The same for quantised coefficients (2.0 files: 16-byte records, bit streams).
  ASSERT_EQ(run("sweep " + smoothFile() + " --thresholds 0.002,0.01 --precision quant -o " + prefix + "q --json", &out), 0)
      << lastStderr();
  const nlohmann::json jq = nlohmann::json::parse(slurp(prefix + "q.json"));
  ASSERT_EQ(run(smoothFile() + " -o " + real + " --threshold 0.01 --precision quant -q"), 0);
  int checked = 0;
  for (const auto& r : jq["rows"])
    if (r["base"] == "all" && std::fabs(r["threshold"].get<double>() - 0.01) < 1e-9) {
      EXPECT_EQ(r["bytes"].get<uint64_t>(), fs::file_size(real));
      ++checked;
    }
  EXPECT_EQ(checked, 1);
  EXPECT_NE(run("sweep " + smoothFile() + " --precision quant -o " + prefix + "q0"), 0);  // the default list has 0
  const std::string png = slurp(prefix + ".png");
  ASSERT_GT(png.size(), 1000u);
  EXPECT_EQ(png.substr(1, 3), "PNG");
}

// Writes the input of the frozen file tests/haar/data/small_v1_0.chaar (see data/README.md):
//   CANOPY_HAAR_FIXTURE=small.light.vdb test_haar_tool --gtest_also_run_disabled_tests
//       --gtest_filter=*WriteFrozenFixtureInput
TEST(HaarTool, DISABLED_WriteFrozenFixtureInput) {
  const char* path = std::getenv("CANOPY_HAAR_FIXTURE");
  ASSERT_NE(path, nullptr);
  const char* n = std::getenv("CANOPY_HAAR_FIXTURE_EDGE");  // optional: an N^3 field instead
  const LatticeGeom g = n ? makeGeom(std::atoi(n), std::atoi(n), std::atoi(n)) : makeGeom(6, 5, 6, -2, 1, 0);
  writeLightVdb(path, g, smoothSet(g));
}
