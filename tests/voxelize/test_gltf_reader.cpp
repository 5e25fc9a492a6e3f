// test_gltf_reader.cpp: the glTF loader never trusts its input (run under ASan/UBSan: the loader,
// tinygltf and stb are compiled into this test with the sanitizers).
//
// Every prefix of a valid .glb (the sample plant, with an alpha-masked PNG texture), thousands of
// single-byte corruptions, a wrong GLB version and bad Draco indices must each either load or
// throw canopy::Error; never crash, hang or read out of bounds.
#include <gtest/gtest.h>

#include <random>

#include "canopy/errors.h"
#include "test_helpers.h"

using namespace canopy;

namespace {

// Loads from memory; returns 0 on success, else the error's exit code.
int tryLoad(const std::vector<uint8_t>& bytes) {
  try {
    const mesh::Mesh m = mesh::loadGltfFromMemory(bytes.data(), bytes.size(), true, ".", "mem.glb");
    mesh::requireFinite(m, "mem.glb");
    return 0;
  } catch (const Error& e) {
    EXPECT_EQ(std::string(e.what()).find('\n'), std::string::npos) << "one-line errors";
    return int(e.code());
  }
}

}  // namespace

TEST(GltfReader, SamplePlantLoads) {
  const auto glb = samplePlantGlb();
  const mesh::Mesh m = mesh::loadGltfFromMemory(glb.data(), glb.size(), true, ".", "sample.glb");
  EXPECT_GT(m.triangles.size(), 500u);
  ASSERT_EQ(m.materials.size(), 3u);  // bark, leaves, glTF default
  EXPECT_EQ(m.materials[1].alphaMode, mesh::AlphaMode::Mask);
  ASSERT_EQ(m.textures.size(), 1u);
  EXPECT_EQ(m.textures[0].width, 64);
}

TEST(GltfReader, EveryTruncatedPrefixFailsCleanly) {
  const auto glb = samplePlantGlb();
  // Every prefix through the JSON chunk and the first KiB of binary, then every 7th byte.
  const size_t dense = std::min(glb.size(), size_t(4096));
  int failed = 0;
  for (size_t n = 0; n < glb.size(); n += (n < dense ? 1 : 7)) {
    std::vector<uint8_t> cut(glb.begin(), glb.begin() + long(n));
    const int code = tryLoad(cut);
    EXPECT_NE(code, 0) << "a " << n << "-byte prefix of " << glb.size() << " loaded";
    failed += code != 0;
  }
  EXPECT_GT(failed, 4000);
}

TEST(GltfReader, FlippedBytesNeverCrash) {
  const auto glb = samplePlantGlb();
  std::mt19937 rng(12345);
  for (int trial = 0; trial < 1500; ++trial) {
    auto b = glb;
    const int flips = 1 + trial % 4;
    for (int f = 0; f < flips; ++f) {
      const size_t at = rng() % b.size();
      b[at] = uint8_t(b[at] ^ (1u << (rng() % 8)));
    }
    tryLoad(b);  // must return or throw canopy::Error
  }
}

TEST(GltfReader, WrongVersionAndMagicAreRejected) {
  auto glb = samplePlantGlb();
  auto v1 = glb;
  v1[4] = 1;
  EXPECT_EQ(tryLoad(v1), int(ExitCode::Unsupported));
  auto bad = glb;
  bad[0] = 'X';
  EXPECT_EQ(tryLoad(bad), int(ExitCode::InvalidInput));
}

TEST(GltfReader, BadDracoIndicesAreRejected) {
  test::GltfParts g = test::triangleGltf({0, 0, 0, 1, 0, 0, 0, 1, 0}, {0, 1, 2});
  g.doc["meshes"][0]["primitives"][0]["extensions"] = {
      {"KHR_draco_mesh_compression", {{"bufferView", 99}, {"attributes", {{"POSITION", 0}}}}}};
  EXPECT_EQ(tryLoad(test::toGlb(g)), int(ExitCode::InvalidInput));
  g.doc["meshes"][0]["primitives"][0]["extensions"]["KHR_draco_mesh_compression"]["bufferView"] = 0;
  EXPECT_EQ(tryLoad(test::toGlb(g)), int(ExitCode::InvalidInput));  // not a Draco stream
}

TEST(GltfReader, RealDracoAssetMatchesPlain) {
  const std::string dir = std::string(CANOPY_SHARED_DIR) + "/assets/plants/";
  const mesh::Mesh a = mesh::loadMesh(dir + "oak_medium.glb");
  const mesh::Mesh b = mesh::loadMesh(dir + "oak_medium.draco.glb");
  ASSERT_EQ(a.triangles.size(), b.triangles.size());
  ASSERT_EQ(a.textures.size(), 2u);
  EXPECT_EQ(a.textures[1].width, 1024);
}
