// The lattice loader and the parameter reader under AddressSanitizer/UBSan (this test compiles
// lattice_io.cpp and params.cpp itself, see CMakeLists.txt): truncated prefixes (every one through
// the first KB, then a sample) and flipped bytes (a sample) of a valid lattice file fail with a
// canopy::Error, never a crash; every truncated prefix of a parameter file is rejected cleanly.
#include <gtest/gtest.h>

#include <fstream>
#include <sstream>

#include "canopy/errors.h"
#include "fixtures.h"
#include "lattice_io.h"
#include "params.h"

using namespace canopy;

namespace {
std::string slurp(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::ostringstream s;
  s << in.rdbuf();
  return s.str();
}
void spit(const std::string& path, const std::string& bytes) {
  std::ofstream(path, std::ios::binary | std::ios::trunc).write(bytes.data(), std::streamsize(bytes.size()));
}
// Loads `path`; returns the exit code of the canopy::Error thrown, or Ok.
ExitCode loadCode(const std::string& path) {
  try {
    lb::loadDensityLattice(path, 0.5);
    return ExitCode::Ok;
  } catch (const Error& e) {
    return e.code();
  }
}
}  // namespace

TEST(LatticeInput, EveryTruncatedPrefixAndFlippedByteFailsCleanly) {
  const std::string dir = fixtures::scratch("inputs");
  const fixtures::Plant plant = fixtures::makePlant(6);
  fixtures::writePlant(dir + "/p.vdb", plant);
  const std::string good = slurp(dir + "/p.vdb");
  ASSERT_EQ(loadCode(dir + "/p.vdb"), ExitCode::Ok);
  const lb::LoadedLattice L = lb::loadDensityLattice(dir + "/p.vdb", 0.5);
  EXPECT_EQ(L.dense.dims.count(), 216);
  EXPECT_EQ(L.density, plant.density);

  const std::string bad = dir + "/bad.vdb";
  // Every prefix through the header and the first grid's metadata, then every 61st byte (the file
  // is ~20 KB and each load costs milliseconds); every 97th byte flipped.
  for (size_t n = 0; n < good.size(); n += (n < 1024 ? 1 : 61)) {
    spit(bad, good.substr(0, n));
    const ExitCode c = loadCode(bad);
    ASSERT_TRUE(c == ExitCode::InvalidInput || c == ExitCode::Io) << "prefix " << n << " code " << int(c);
  }
  for (size_t i = 0; i < good.size(); i += 97) {
    std::string flipped = good;
    flipped[i] = char(flipped[i] ^ 0x5a);
    spit(bad, flipped);
    ASSERT_EQ(loadCode(bad), ExitCode::InvalidInput) << "byte " << i;
  }
}

TEST(ParamsInput, EveryTruncatedPrefixIsRejected) {
  const std::string dir = fixtures::scratch("params");
  const std::string text =
      R"({"sigma_a": [0.1, 0.09, 0.12], "fs": [0.05, 0.15, 0.02], "bs": 0.07, "wood_g": -0.9, "wood_threshold": 0.4})";
  spit(dir + "/p.json", text);
  const lb::LightParams p = lb::loadParams(dir + "/p.json");
  EXPECT_EQ(p.woodThreshold, 0.4);
  EXPECT_NEAR(p.g[1], (0.15 - 0.07) / 0.22, 1e-12);
  for (size_t n = 0; n < text.size(); ++n) {
    spit(dir + "/t.json", text.substr(0, n));
    try {
      lb::loadParams(dir + "/t.json");
      ADD_FAILURE() << "prefix " << n << " accepted";
    } catch (const Error& e) {
      EXPECT_EQ(e.code(), ExitCode::InvalidInput) << n;
    }
  }
}
