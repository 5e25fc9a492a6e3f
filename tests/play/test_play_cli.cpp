// test_play_cli.cpp: canopy-play's command line as data: command, expected exit code, expected
// files and report fields (CONVENTIONS.md 12). Runs the built executable.
#include <gtest/gtest.h>

#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "canopy/atomic_file.h"
#include "canopy/device.h"
#include "canopy/errors.h"
#include "runtime/player.h"
#include "runtime/image_io.h"
#include "tests/play/scenes.h"

namespace pt = canopy::play::testing;

namespace {

const std::string kBin = std::string(CANOPY_BINARY_DIR) + "/bin/canopy-play";

struct CliRun {
  int code;
  std::string out, err;
};

CliRun run(const std::string& args) {
  const std::string dir = pt::tmpDir("cli");
  // per process: ctest runs the cases of this file as parallel processes
  const std::string tag = std::to_string(::getpid());
  const std::string o = dir + "/stdout." + tag + ".txt", e = dir + "/stderr." + tag + ".txt";
  const std::string cmd = "'" + kBin + "' " + args + " > '" + o + "' 2> '" + e + "'";
  const int status = std::system(cmd.c_str());
  CliRun r{WIFEXITED(status) ? WEXITSTATUS(status) : -1, {}, {}};
  std::stringstream so, se;
  so << std::ifstream(o).rdbuf();
  se << std::ifstream(e).rdbuf();
  r.out = so.str();
  r.err = se.str();
  return r;
}

bool exists(const std::string& p) {
  struct stat st;
  return ::stat(p.c_str(), &st) == 0;
}

// The ball (raw pages; `compressed`: the same with compressed pages, format 5.0).
const std::string& sceneFile(bool compressed = false) {
  static const auto ball = [](const char* name, uint32_t coding) {
    const std::string f = pt::tmpDir("cli") + "/" + name;
    const float albedo[3] = {0.2f, 0.6f, 0.1f};
    pt::writeScene(f, {pt::sphereModel(24, 10, 0.4f, 0.1f, albedo)}, {pt::instanceAt(0, 0, 0, 0)}, coding);
    return f;
  };
  static const std::string p[2] = {ball("ball.canopy", canopy::kCanopyPageRaw), ball("ball-zstd.canopy", canopy::kCanopyPageZstd)};
  return p[compressed ? 1 : 0];
}

}  // namespace

TEST(PlayCli, WritesAPngOfTheRequestedSizeThatIsNotBlank) {
  const std::string out = pt::tmpDir("cli") + "/ball.png";
  std::remove(out.c_str());
  const CliRun r = run("'" + sceneFile() + "' -o '" + out + "' --size 40x30 --device cpu --json");
  ASSERT_EQ(r.code, 0) << r.err;
  int w = 0, h = 0;
  const std::vector<unsigned char> px = canopy::play::readPngRgb(out, w, h);
  EXPECT_EQ(w, 40);
  EXPECT_EQ(h, 30);
  int fg = 0;
  for (size_t i = 0; i < px.size(); i += 3) fg += px[i] != px[0] || px[i + 1] != px[1] || px[i + 2] != px[2];
  EXPECT_GT(fg, 100);  // the ball covers a good part of the frame
  const nlohmann::json j = nlohmann::json::parse(r.out);
  EXPECT_EQ(j["frames"], 1);
  EXPECT_EQ(j["device"], "cpu");
  for (const char* k : {"frame_ms_median", "frame_ms_p95", "cache_hit_rate", "pages_streamed", "mb_streamed", "file_mb_read", "stream_mb_per_s"})
    EXPECT_TRUE(j.contains(k)) << k;
  EXPECT_NE(r.err.find("median"), std::string::npos) << r.err;  // the summary on stderr
  // the same input gives the same bytes (a converged frame does not depend on loader timing)
  const std::string again = pt::tmpDir("cli") + "/ball-again.png";
  ASSERT_EQ(run("'" + sceneFile() + "' -o '" + again + "' --size 40x30 --device cpu --quiet").code, 0);
  EXPECT_EQ(canopy::readFile(out), canopy::readFile(again));
  // raw pages: the file bytes read are the pages' images; compressed pages (5.0): fewer bytes read,
  // the same image
  EXPECT_EQ(j["file_mb_read"], j["mb_streamed"]);
  const std::string packed = pt::tmpDir("cli") + "/ball-zstd.png";
  const CliRun z = run("'" + sceneFile(true) + "' -o '" + packed + "' --size 40x30 --device cpu --json --quiet");
  ASSERT_EQ(z.code, 0) << z.err;
  const nlohmann::json jz = nlohmann::json::parse(z.out);
  EXPECT_EQ(jz["mb_streamed"], j["mb_streamed"]);
  EXPECT_LT(jz["file_mb_read"].get<double>(), 0.5 * jz["mb_streamed"].get<double>());
  EXPECT_EQ(canopy::readFile(packed), canopy::readFile(out));
}

// --no-empty-skip marches the brick cells that the skip would pass over (the ball's bricks on its
// edge hold empty cells): the sample phase changes, the image barely (8-bit PNG values within 4).
TEST(PlayCli, NoEmptySkipGivesNearlyTheSameImage) {
  const std::string a = pt::tmpDir("cli") + "/ball-skip.png", b = pt::tmpDir("cli") + "/ball-noskip.png";
  ASSERT_EQ(run("'" + sceneFile() + "' -o '" + a + "' --size 40x30 --device cpu --quiet").code, 0);
  const CliRun r = run("'" + sceneFile() + "' -o '" + b + "' --size 40x30 --device cpu --quiet --no-empty-skip");
  ASSERT_EQ(r.code, 0) << r.err;
  int w = 0, h = 0, w2 = 0, h2 = 0;
  const std::vector<unsigned char> pa = canopy::play::readPngRgb(a, w, h), pb = canopy::play::readPngRgb(b, w2, h2);
  ASSERT_EQ(pa.size(), pb.size());
  int maxDiff = 0, differ = 0;
  for (size_t i = 0; i < pa.size(); ++i) {
    maxDiff = std::max(maxDiff, std::abs(int(pa[i]) - int(pb[i])));
    differ += pa[i] != pb[i];
  }
  EXPECT_GT(differ, 0);    // the flag took effect
  EXPECT_LE(maxDiff, 4);   // measured 3 (of 255) at the ball's rim
}

TEST(PlayCli, WritesAnExrSequenceFromAPattern) {
  const std::string dir = pt::tmpDir("cli/seq");
  const CliRun r = run("'" + sceneFile() + "' -o '" + dir + "/f_%02d.exr' --frames 3 --size 16x16 --device cpu "
                    "--camera orbit:turns=0.1 --sun orbit:turns=0.05 --quiet");
  ASSERT_EQ(r.code, 0) << r.err;
  for (const char* f : {"/f_00.exr", "/f_01.exr", "/f_02.exr"}) EXPECT_TRUE(exists(dir + f)) << f;
  EXPECT_TRUE(r.err.empty()) << r.err;  // --quiet
}

TEST(PlayCli, GpuDeviceWithoutAGpuExitsUnsupported) {
  if (canopy::cudaDeviceCount() > 0) GTEST_SKIP() << "a GPU is present";
  const std::string out = pt::tmpDir("cli") + "/nogpu.png";
  std::remove(out.c_str());
  const CliRun r = run("'" + sceneFile() + "' -o '" + out + "' --size 8x8 --device cuda");
  EXPECT_EQ(r.code, 5) << r.err;
  EXPECT_FALSE(exists(out));
}

// --light exact on a Haar-lit file (format 1.1) through the executable: the report names the mode
// and the Haar pages, and the frame is written; on a file without Haar light it is the fast path.
TEST(PlayCli, LightExactReadsTheHaarPages) {
  const std::string dir = pt::tmpDir("cli");
  const std::string haar = dir + "/ball-haar.canopy", out = dir + "/exact.png";
  const float rgb[3] = {1.0f, 0.5f, 0.25f};
  pt::writeHaarLitScene(haar, {pt::sphereModel(24, 10, 0.4f)}, {pt::rampLight(rgb, 1.0f, 24)}, {pt::instanceAt(0, 0, 0, 0)}, 0.01f,
                        canopy::haar::Precision::Fp16);
  for (const char* mode : {"exact", "fast"}) {
    std::remove(out.c_str());
    const CliRun r = run("'" + haar + "' -o '" + out + "' --size 32x24 --device cpu --light " + mode + " --json -q");
    ASSERT_EQ(r.code, 0) << r.err;
    const nlohmann::json j = nlohmann::json::parse(r.out);
    EXPECT_EQ(j["light"], mode);
    EXPECT_GT(double(j["haar_page_mb"]), 0.0);
    EXPECT_EQ(int(j["lit_models"]), 1);
    EXPECT_TRUE(exists(out));
  }
}

TEST(PlayCli, ErrorsHaveDocumentedExitCodesAndLeaveNoOutput) {
  const std::string dir = pt::tmpDir("cli/errors");
  const std::string out = dir + "/x.png";
  struct Case {
    std::string args;
    int code;
    const char* message;
  };
  const std::vector<unsigned char> bytes = canopy::readFile(sceneFile());
  const std::string truncated = dir + "/truncated.canopy";
  canopy::writeFileAtomic(truncated, bytes.data(), bytes.size() / 2);
  const std::string badPath = dir + "/bad-path.json";
  std::ofstream(badPath) << R"({"keyframes":[{"frame":0,"position":[0,0,5]}]})";  // no target
  // A camera 1e20 m away made NaN ray positions (float squares overflow) and crashed the descent.
  const std::string farPath = dir + "/far.json";
  std::ofstream(farPath) << R"({"keyframes":[{"frame":0,"position":[1e20,0,0],"target":[0,0,0]}]})";
  const std::string hugePath = dir + "/huge.json";
  std::ofstream(hugePath) << R"({"keyframes":[{"frame":0,"position":[1,0,0],"target":[1e39,0,0]}]})";
  const std::string sunPath = dir + "/sun.json";
  std::ofstream(sunPath) << R"({"keyframes":[{"frame":0,"direction":[1e20,1e20,0]}]})";
  const std::vector<Case> cases = {
      {"'" + sceneFile() + "' -o '" + out + "' --camera '" + badPath + "' --device cpu", 3, "target"},
      {"'" + dir + "/missing.canopy' -o '" + out + "' --device cpu", 2, "missing.canopy"},
      {"'" + truncated + "' -o '" + out + "' --device cpu", 3, "truncated.canopy"},
      {"'" + sceneFile() + "' -o '" + out + "' --size 40by30 --device cpu", 1, "--size"},
      {"'" + sceneFile() + "' -o '" + dir + "/x.jpg' --device cpu", 1, ".png or .exr"},
      {"'" + sceneFile() + "' -o '" + out + "' --frames 3 --device cpu", 1, "pattern"},
      {"'" + sceneFile() + "' -o '" + out + "' --sun 1,2 --device cpu", 1, "--sun"},
      {"'" + sceneFile() + "' -o '" + out + "' --lod-bias nan --device cpu", 1, "finite"},
      {"'" + sceneFile() + "' -o '" + out + "' --step 0 --device cpu", 1, "--step"},
      {"'" + sceneFile() + "' -o '" + out + "' --step-growth 2 --device cpu", 1, "--step-growth"},
      {"'" + sceneFile() + "' -o '" + out + "' --step-growth nan --device cpu", 1, "--step-growth"},
      {"'" + sceneFile() + "' -o '" + out + "' --step-growth 0.1 --step-growth-max 0.5 --device cpu", 1, "--step-growth-max"},
      {"'" + sceneFile() + "' -o '" + out + "' --far-field near --device cpu", 1, "--far-field"},
      {"'" + sceneFile() + "' -o '" + out + "' --far-field 0 --device cpu", 1, "--far-field"},
      {"'" + sceneFile() + "' -o '" + out + "' --far-field -5 --device cpu", 1, "--far-field"},
      {"'" + sceneFile() + "' -o '" + out + "' --far-field nan --device cpu", 1, "--far-field"},
      {"'" + sceneFile() + "' -o '" + out + "' --camera orbit:zoom=2 --device cpu", 1, "zoom"},
      {"'" + sceneFile() + "' -o '" + dir + "/no-such-dir/x.png' --size 8x8 --device cpu", 2, "no-such-dir"},
      {"'" + sceneFile() + "' -o '" + out + "' --camera '" + dir + "/missing.json' --device cpu", 2, "missing.json"},
      {"'" + sceneFile() + "' -o '" + out + "' --shadows rays --device cpu", 1, "--shadows"},
      {"'" + sceneFile() + "' -o '" + out + "' --shadow-map-cells 0 --device cpu", 1, "--shadow-map-cells"},
      {"'" + sceneFile() + "' -o '" + out + "' --shadow-map-bias -1 --device cpu", 1, "--shadow-map-bias"},
      {"'" + sceneFile() + "' -o '" + out + "' --warp-tile 3 --device cpu", 1, "--warp-tile"},
      {"'" + sceneFile() + "' -o '" + out + "' --stereo-holes random --device cpu", 1, "--stereo-holes must be tile or kind"},
      {"'" + sceneFile() + "' -o '" + out + "' --stereo-hole-blocks 8 --device cpu", 1, "--stereo-hole-blocks must be 0 or 6"},
      {"'" + sceneFile() + "' -o '" + out + "' --light precise --device cpu", 1, "--light"},
      {"'" + sceneFile() + "' -o '" + out + "' --camera '" + farPath + "' --device cpu", 3,
       "far.json: the camera at frame 0 is more than 10^4 scene radii"},
      {"'" + sceneFile() + "' -o '" + out + "' --camera '" + hugePath + "' --device cpu", 3,
       "huge.json: keyframe 0 target: not finite (in single precision)"},
      {"'" + sceneFile() + "' -o '" + out + "' --camera orbit:distance=1e30 --device cpu", 1,
       "--camera: the orbit puts the camera 1e+30 m from the scene's centre, more than 10^4 scene radii"},
      {"'" + sceneFile() + "' -o '" + out + "' --camera orbit:distance=1e39 --device cpu", 1, "bad number '1e39'"},
      {"'" + sceneFile() + "' -o '" + out + "' --sun 1e999,0,0 --device cpu", 1, "--sun '1e999,0,0'"},
      {"'" + sceneFile() + "' -o '" + out + "' --sun '" + sunPath + "' --device cpu", 3, "zero or overflowing sun direction"},
      {"'" + sceneFile() + "' -o '" + out + "' --ground grass --device cpu", 1, "--ground 'grass': expected none, auto or a height"},
      {"'" + sceneFile() + "' -o '" + out + "' --ground 1e12 --device cpu", 1, "--ground '1e12'"},
      {"'" + sceneFile() + "' -o '" + out + "' --ground nan --device cpu", 1, "--ground 'nan'"},
      {"'" + sceneFile() + "' -o '" + out + "' --ground-albedo 1.5 --device cpu", 1, "--ground-albedo must be"},
      {"'" + sceneFile() + "' -o '" + out + "' --ground-albedo 0.1,0.2 --device cpu", 1, "--ground-albedo '0.1,0.2'"},
      {"'" + sceneFile() + "' -o '" + out + "' --ground-albedo '0.2 0.3 0.4' --device cpu", 1, "--ground-albedo '0.2 0.3 0.4'"},
      {"'" + sceneFile() + "' -o '" + out + "' --ground-albedo 0.5x --device cpu", 1, "--ground-albedo '0.5x'"},
  };
  for (const Case& c : cases) {
    std::remove(out.c_str());
    const CliRun r = run(c.args);
    EXPECT_EQ(r.code, c.code) << c.args << "\n" << r.err;
    EXPECT_NE(r.err.find(c.message), std::string::npos) << c.args << "\n" << r.err;
    EXPECT_FALSE(exists(out)) << c.args;
  }
}

// -o is a pattern the tool formats itself: exactly one %d / %Nd / %0Nd, "%%" for a literal '%'.
TEST(PlayCli, FrameFileNameFormatsTheOneIntegerConversion) {
  using canopy::play::frameFileName;
  EXPECT_EQ(frameFileName("f/f_%04d.exr", 7, 10), "f/f_0007.exr");
  EXPECT_EQ(frameFileName("f_%d.png", 123, 200), "f_123.png");
  EXPECT_EQ(frameFileName("f_%3d.png", 7, 10), "f_  7.png");
  EXPECT_EQ(frameFileName("f_%02d.png", 1234, 2000), "f_1234.png");  // the width is a minimum
  EXPECT_EQ(frameFileName("100%%_%02d.png", 5, 10), "100%_05.png");
  EXPECT_EQ(frameFileName("plain.png", 0, 1), "plain.png");
  for (const char* bad : {"f_%s.png", "f_%n.png", "g_%d_%d.png", "f_%i.png", "f_%ld.png", "f_%-4d.png", "f_%.2d.png",
                          "f_%x.png", "f_%040d.png", "f_%", "f_%04", "only%%.png", "%%%d%.png"}) {
    try {
      frameFileName(bad, 0, 2);
      ADD_FAILURE() << bad << " was accepted";
    } catch (const canopy::Error& e) {
      EXPECT_EQ(e.code(), canopy::ExitCode::Usage) << bad;
      EXPECT_NE(std::string(e.what()).find(bad), std::string::npos) << e.what();
    }
  }
}

namespace {
std::vector<std::string> filesIn(const std::string& dir) {
  std::vector<std::string> names;
  for (const auto& e : std::filesystem::directory_iterator(dir)) names.push_back(e.path().filename().string());
  std::sort(names.begin(), names.end());
  return names;
}
}  // namespace

// Before the fix %s and %n reached printf (a crash after writing f_(null).png) and %d_%d read stack
// garbage into the names; now they are usage errors found before any work, leaving nothing.
TEST(PlayCli, BadFramePatternIsAUsageErrorAndWritesNothing) {
  const std::string dir = pt::tmpDir("cli/bad-pattern");
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  for (const char* pattern : {"f_%s.png", "f_%n.png", "g_%d_%d.png", "f_%p.exr"}) {
    const CliRun r = run("'" + sceneFile() + "' -o '" + dir + "/" + pattern + "' --size 16x16 --frames 2 --device cpu");
    EXPECT_EQ(r.code, 1) << pattern << "\n" << r.err;
    EXPECT_NE(r.err.find("one integer conversion such as %04d"), std::string::npos) << r.err;
    EXPECT_EQ(filesIn(dir), std::vector<std::string>{}) << pattern;
  }
}

// A sequence that fails midway (frame 1's path is a directory) removes the frames it wrote.
TEST(PlayCli, FailedSequenceRemovesTheFramesItWrote) {
  const std::string dir = pt::tmpDir("cli/failed-seq");
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir + "/f_01.png");
  const CliRun r = run("'" + sceneFile() + "' -o '" + dir + "/f_%02d.png' --size 16x16 --frames 3 --device cpu -q");
  EXPECT_EQ(r.code, 2) << r.err;
  EXPECT_NE(r.err.find("f_01.png"), std::string::npos) << r.err;
  EXPECT_EQ(filesIn(dir), std::vector<std::string>{"f_01.png"});  // only the directory that was there
}
