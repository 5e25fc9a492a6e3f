// test_gltf_reader.cpp: the glTF and PLY loaders never trust their input (run under ASan/UBSan:
// the loaders, tinygltf and stb are compiled into this test with the sanitizers).
//
// Every prefix of a valid .glb (the sample plant, with an alpha-masked PNG texture), thousands of
// single-byte corruptions, a wrong GLB version and bad Draco indices must each either load or
// throw canopy::Error; never crash, hang or read out of bounds.
#include <gtest/gtest.h>

#include <chrono>
#include <cstdlib>
#include <cstring>
#include <future>
#include <iostream>
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
  // the same mesh, less the slivers the Draco encoder dropped (13619 of 13806 in the shared file)
  ASSERT_LE(b.triangles.size(), a.triangles.size());
  ASSERT_GE(double(b.triangles.size()), 0.97 * double(a.triangles.size()));
  ASSERT_EQ(a.textures.size(), 2u);
  EXPECT_EQ(a.textures[1].width, 1024);
}

// ---- PLY (ply_loader.cpp) --------------------------------------------------------------------
namespace {

const float kCubeV[8][3] = {{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0}, {0, 0, 1}, {1, 0, 1}, {1, 1, 1}, {0, 1, 1}};
const int kCubeF[6][4] = {{0, 3, 2, 1}, {4, 5, 6, 7}, {0, 1, 5, 4}, {2, 3, 7, 6}, {1, 2, 6, 5}, {0, 4, 7, 3}};

// The unit cube as 6 quads with red faces (ASCII).
std::string asciiCubePly() {
  std::string s = "ply\nformat ascii 1.0\ncomment a cube\nelement vertex 8\nproperty float x\nproperty float y\n"
                  "property float z\nelement face 6\nproperty list uchar int vertex_indices\n"
                  "property uchar red\nproperty uchar green\nproperty uchar blue\nend_header\n";
  for (auto& v : kCubeV) s += std::to_string(v[0]) + " " + std::to_string(v[1]) + " " + std::to_string(v[2]) + "\n";
  for (auto& f : kCubeF)
    s += "4 " + std::to_string(f[0]) + " " + std::to_string(f[1]) + " " + std::to_string(f[2]) + " " +
         std::to_string(f[3]) + " 255 0 0\n";
  return s;
}

// The same cube in binary (little or big endian) with green vertex colours and double x.
std::vector<uint8_t> binaryCubePly(bool bigEndian) {
  const std::string h = std::string("ply\nformat ") + (bigEndian ? "binary_big_endian" : "binary_little_endian") +
                        " 1.0\nelement vertex 8\nproperty double x\nproperty float y\nproperty float z\n"
                        "property uchar red\nproperty uchar green\nproperty uchar blue\n"
                        "element face 6\nproperty list uchar uint vertex_indices\nend_header\n";
  std::vector<uint8_t> b(h.begin(), h.end());
  auto put = [&](const void* p, size_t n) {
    const uint8_t* c = static_cast<const uint8_t*>(p);
    for (size_t i = 0; i < n; ++i) b.push_back(c[bigEndian ? n - 1 - i : i]);
  };
  for (auto& v : kCubeV) {
    const double x = v[0];
    put(&x, 8);
    put(&v[1], 4);
    put(&v[2], 4);
    const uint8_t rgb[3] = {0, 255, 0};
    b.insert(b.end(), rgb, rgb + 3);
  }
  for (auto& f : kCubeF) {
    b.push_back(4);
    for (int k = 0; k < 4; ++k) {
      const uint32_t i = uint32_t(f[k]);
      put(&i, 4);
    }
  }
  return b;
}

std::vector<uint8_t> bytesOf(const std::string& s) { return std::vector<uint8_t>(s.begin(), s.end()); }

using MemoryLoader = mesh::Mesh (*)(const uint8_t*, size_t, const std::string&);

// Loads from memory: 0 on success, else the error's exit code; `what` gets the message.
int tryLoad(MemoryLoader load, const char* name, const std::vector<uint8_t>& b, std::string* what = nullptr) {
  try {
    const mesh::Mesh m = load(b.data(), b.size(), name);
    mesh::requireFinite(m, name);
    return 0;
  } catch (const Error& e) {
    EXPECT_EQ(std::string(e.what()).find('\n'), std::string::npos) << "one-line errors";
    if (what) *what = e.what();
    return int(e.code());
  }
}

int tryPly(const std::vector<uint8_t>& b, std::string* what = nullptr) {
  return tryLoad(mesh::loadPlyFromMemory, "mem.ply", b, what);
}

// Runs f under a watchdog: OpenMesh's PLY reader used to loop forever on truncated files, and
// such a hang must fail this test rather than stall the suite.
void withinSeconds(int seconds, const std::function<void()>& f) {
  auto done = std::async(std::launch::async, f);
  if (done.wait_for(std::chrono::seconds(seconds)) != std::future_status::ready) {
    std::cerr << "the reader did not finish within " << seconds << " s (hang)\n";
    std::_Exit(1);
  }
  done.get();
}


using TryFn = std::function<int(const std::vector<uint8_t>&)>;

// Every prefix of `whole` loads (0) or fails with exit 3; at most maxValid of them load (a text
// file cut inside or after its last value is still valid); `whole` itself loads.
void expectEveryPrefixFinishes(const TryFn& load, const std::vector<uint8_t>& whole, int maxValid) {
  int failed = 0;
  for (size_t n = 0; n < whole.size(); ++n) {
    const std::vector<uint8_t> cut(whole.begin(), whole.begin() + long(n));
    const int code = load(cut);
    EXPECT_TRUE(code == 0 || code == int(ExitCode::InvalidInput)) << n << " bytes: code " << code;
    failed += code != 0;
  }
  EXPECT_GE(failed, int(whole.size()) - maxValid);
  EXPECT_EQ(load(whole), 0);
}

// 2000 copies of `whole` with 1 to 3 flipped bits each load or fail with one of `codes`.
void expectFlippedBytesFinish(const TryFn& load, const std::vector<uint8_t>& whole, std::mt19937& rng,
                              std::initializer_list<ExitCode> codes) {
  for (int trial = 0; trial < 2000; ++trial) {
    auto b = whole;
    for (int f = 0; f < 1 + trial % 3; ++f) {
      const size_t at = rng() % b.size();
      b[at] = uint8_t(b[at] ^ (1u << (rng() % 8)));
    }
    const int code = load(b);
    bool known = code == 0;
    for (ExitCode c : codes) known |= code == int(c);
    EXPECT_TRUE(known) << "code " << code;
  }
}

}  // namespace

TEST(PlyReader, AsciiAndBinaryCubesLoad) {
  std::string what;
  const auto a = bytesOf(asciiCubePly());
  const mesh::Mesh ma = mesh::loadPlyFromMemory(a.data(), a.size(), "a.ply");
  ASSERT_EQ(ma.triangles.size(), 12u);  // 6 quads fanned
  ASSERT_TRUE(ma.hasTriangleColors);
  EXPECT_FLOAT_EQ(ma.triangles[0].color[0], 1.f);
  EXPECT_FLOAT_EQ(ma.triangles[0].color[1], 0.f);
  for (bool be : {false, true}) {
    SCOPED_TRACE(be ? "big endian" : "little endian");
    const auto b = binaryCubePly(be);
    const mesh::Mesh mb = mesh::loadPlyFromMemory(b.data(), b.size(), "b.ply");
    ASSERT_EQ(mb.triangles.size(), 12u);
    for (size_t t = 0; t < 12; ++t)
      for (int v = 0; v < 3; ++v)
        for (int k = 0; k < 3; ++k) EXPECT_EQ(mb.triangles[t].p[size_t(v)][size_t(k)], ma.triangles[t].p[size_t(v)][size_t(k)]);
    EXPECT_FLOAT_EQ(mb.triangles[0].color[1], 1.f);  // green vertices
    EXPECT_FLOAT_EQ(mb.triangles[0].color[0], 0.f);
  }
}

// Every prefix of a small ASCII and a small binary PLY finishes at once with exit 3 or a valid
// mesh (an ASCII prefix cut inside the last number is still a valid file).
TEST(PlyReader, EveryTruncatedPrefixFinishes) {
  withinSeconds(120, [] {
    for (const auto& whole : {bytesOf(asciiCubePly()), binaryCubePly(false), binaryCubePly(true)})
      expectEveryPrefixFinishes([](const auto& b) { return tryPly(b); }, whole, 4);
  });
}

TEST(PlyReader, FlippedBytesNeverCrashOrHang) {
  withinSeconds(120, [] {
    std::mt19937 rng(4321);
    for (const auto& whole : {bytesOf(asciiCubePly()), binaryCubePly(false)})
      expectFlippedBytesFinish([](const auto& b) { return tryPly(b); }, whole, rng, {ExitCode::InvalidInput});
  });
}

TEST(PlyReader, PreciseReasons) {
  struct Case {
    std::string ply, reason;
  };
  const std::string v3 = "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n";
  const std::vector<Case> cases = {
      {"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\n", "mem.ply: truncated PLY header"},
      {"plx\n", "not a PLY file"},
      {"ply\nelement vertex 3\nproperty float x\nend_header\n", "no format line"},
      {"ply\nformat binary_middle_endian 1.0\nend_header\n", "unknown PLY format"},
      {v3 + "property quad w\nend_header\n", "unknown property type 'quad'"},
      {v3 + "end_header\n0 0 0\n1 0 0\n0 1 0\n", "no face element"},
      {v3 + "element face 1\nproperty int vertex_indices\nend_header\n0 0 0\n1 0 0\n0 1 0\n3\n",
       "no list property vertex_indices"},
      {v3 + "element face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n0 1 0\n3 0 1 7\n",
       "PLY face 0 references vertex 7 (the file has 3)"},
      {v3 + "element face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n0 1 0\n3 0 1\n",
       "truncated PLY body (element 'face' 0 of 1 ends early)"},
      {v3 + "element face 1000\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n",
       "truncated PLY body"},
      {v3 + "element face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n9\n",
       "unexpected data after the last PLY element"},
      {v3 + "element face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n0 x 0\n3 0 1 2\n",
       "bad number 'x'"},
      {v3 + "element face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n0 nan 0\n3 0 1 2\n",
       "triangle 0 has a NaN or infinite vertex coordinate"},
      {"ply\nformat binary_little_endian 1.0\nelement vertex 1000000\nproperty float x\nproperty float y\n"
       "property float z\nelement face 0\nproperty list uchar int vertex_indices\nend_header\n\1\2\3",
       "truncated PLY body (3 bytes; the header's elements need at least 12000000)"},
  };
  for (const Case& c : cases) {
    SCOPED_TRACE(c.ply);
    std::string what;
    EXPECT_EQ(tryPly(bytesOf(c.ply), &what), int(ExitCode::InvalidInput));
    EXPECT_NE(what.find(c.reason), std::string::npos) << what;
  }
}

// ---- OFF (off_loader.cpp) --------------------------------------------------------------------
namespace {

// The unit cube as 6 quads: COFF with green vertices (integers, alpha included), comments and
// blank lines in between, or plain OFF with red faces given as floats.
std::string cubeOff(bool vertexColors) {
  std::string s = vertexColors ? "# a cube\nCOFF\n\n8 6 0  # counts\n" : "OFF 8 6 12\n";
  for (auto& v : kCubeV)
    s += std::to_string(v[0]) + " " + std::to_string(v[1]) + " " + std::to_string(v[2]) +
         (vertexColors ? " 0 255 0 255\n" : "\n");
  for (auto& f : kCubeF)
    s += "4 " + std::to_string(f[0]) + " " + std::to_string(f[1]) + " " + std::to_string(f[2]) + " " +
         std::to_string(f[3]) + (vertexColors ? "\n" : " 1.0 0.0 0.0 1.0\n");
  return s;
}

int tryOff(const std::vector<uint8_t>& b, std::string* what = nullptr) {
  return tryLoad(mesh::loadOffFromMemory, "mem.off", b, what);
}

}  // namespace

TEST(OffReader, CubesWithVertexAndFaceColoursLoad) {
  const mesh::Mesh ply = [] {
    const auto a = bytesOf(asciiCubePly());
    return mesh::loadPlyFromMemory(a.data(), a.size(), "a.ply");
  }();
  for (bool vertexColors : {true, false}) {
    SCOPED_TRACE(vertexColors ? "COFF" : "OFF with face colours");
    const auto b = bytesOf(cubeOff(vertexColors));
    const mesh::Mesh m = mesh::loadOffFromMemory(b.data(), b.size(), "cube.off");
    ASSERT_EQ(m.triangles.size(), 12u);  // 6 quads fanned like the PLY reader's
    for (size_t t = 0; t < 12; ++t)
      for (int v = 0; v < 3; ++v)
        for (int k = 0; k < 3; ++k) EXPECT_EQ(m.triangles[t].p[size_t(v)][size_t(k)], ply.triangles[t].p[size_t(v)][size_t(k)]);
    ASSERT_TRUE(m.hasTriangleColors);
    EXPECT_FLOAT_EQ(m.triangles[5].color[0], vertexColors ? 0.f : 1.f);
    EXPECT_FLOAT_EQ(m.triangles[5].color[1], vertexColors ? 1.f : 0.f);
    EXPECT_FLOAT_EQ(m.triangles[5].color[2], 0.f);
  }
  const auto plain = bytesOf("OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n");
  EXPECT_FALSE(mesh::loadOffFromMemory(plain.data(), plain.size(), "p.off").hasTriangleColors);
}

TEST(OffReader, EveryTruncatedPrefixFinishes) {
  withinSeconds(120, [] {
    // Valid prefixes: the last face cut inside or after its last value (with face colours, a
    // colour of fewer than 3 values is a colour-map index or nothing).
    for (bool vertexColors : {true, false})
      expectEveryPrefixFinishes([](const auto& b) { return tryOff(b); }, bytesOf(cubeOff(vertexColors)), vertexColors ? 2 : 18);
  });
}

TEST(OffReader, FlippedBytesNeverCrashOrHang) {
  withinSeconds(120, [] {
    std::mt19937 rng(8765);
    for (bool vertexColors : {true, false})
      expectFlippedBytesFinish([](const auto& b) { return tryOff(b); }, bytesOf(cubeOff(vertexColors)), rng,
                               {ExitCode::InvalidInput, ExitCode::Unsupported});  // a flip can make "4OFF"
  });
}

TEST(OffReader, PreciseReasons) {
  struct Case {
    std::string off, reason;
    ExitCode code = ExitCode::InvalidInput;
  };
  const std::string v3 = "OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n";
  const std::vector<Case> cases = {
      {"", "mem.off: empty OFF file"},
      {"# only a comment\n", "mem.off: empty OFF file"},
      {"PLY\n", "not an OFF file"},
      {"OFF\n", "truncated OFF file (no vertex and face counts)"},
      {"OFF\n-3 1 0\n", "mem.off: line 2: bad OFF counts"},
      {"OFF\n3 x 0\n", "mem.off: line 2: bad OFF counts"},
      {"OFF\n4000000000 2000000000 0\n0 0 0\n",
       "mem.off: the OFF header declares 4000000000 vertices and 2000000000 faces, more than its 34 bytes can hold"},
      {"OFF\n3 1 0\n0 0 0\n1 0 0\n", "truncated OFF file (2 of 3 vertices;"},
      {v3, "truncated OFF file (0 of 1 faces;"},
      {"OFF\n3 1 0\n0 0 0\n1 0\n0 1 0\n3 0 1 2\n", "mem.off: line 4: vertex 1 (counting from 0) has 2 values, 3 expected"},
      {"OFF\n3 1 0\n0 0 0\n1 0 0\n0 nan 0\n3 0 1 2\n", "mem.off: line 5: vertex 2 (counting from 0) has a NaN or infinite coordinate"},
      {"OFF\n3 1 0\n0 0 0\n1 0 0\n0 y 0\n3 0 1 2\n", "vertex 2 (counting from 0) has a coordinate 'y' that is not a number"},
      {"COFF\n3 1 0\n0 0 0 1 1\n1 0 0 1 1 1\n0 1 0 1 1 1\n3 0 1 2\n", "vertex 0 (counting from 0) has 5 values, 6 expected"},
      {v3 + "3 0 1 7\n", "mem.off: line 6: face 0 (counting from 0) refers to vertex '7', but the file has 3 vertices"},
      {v3 + "3 0 1 -1\n", "refers to vertex '-1'"},
      {v3 + "4 0 1 2\n", "face 0 (counting from 0) is not a corner count followed by that many vertex indices"},
      {v3 + "3 0 1 2 x 0 0\n", "colour value 'x' is not a number"},
      {v3 + "3 0 1 2\n3 0 1 2\n", "mem.off: line 7: data after the last of the 1 faces the header declares"},
      {"OFF BINARY\n", "binary OFF files are not supported", ExitCode::Unsupported},
      {"4OFF\n1 0 0\n0 0 0 0\n", "4-D and n-D OFF files are not supported", ExitCode::Unsupported},
  };
  for (const Case& c : cases) {
    SCOPED_TRACE(c.off);
    std::string what;
    EXPECT_EQ(tryOff(bytesOf(c.off), &what), int(c.code));
    EXPECT_NE(what.find(c.reason), std::string::npos) << what;
  }
}
