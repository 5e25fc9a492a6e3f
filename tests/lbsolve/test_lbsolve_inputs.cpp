// The parameter reader under AddressSanitizer/UBSan (this test compiles params.cpp itself, see
// CMakeLists.txt): every truncated prefix of a parameter file is rejected cleanly. The density
// lattice file's reader has its own tests (tests/formats/test_density_lattice.cpp).
#include <gtest/gtest.h>

#include <fstream>
#include <sstream>

#include "canopy/errors.h"
#include "fixtures.h"
#include "params.h"

using namespace canopy;

namespace {
void spit(const std::string& path, const std::string& bytes) {
  std::ofstream(path, std::ios::binary | std::ios::trunc).write(bytes.data(), std::streamsize(bytes.size()));
}
}  // namespace

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
