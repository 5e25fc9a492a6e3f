// test_voxelize_cli.cpp: the canopy-voxelize executable as a user (or make) runs it.
//
// Cases are data: arguments, expected exit code, and what stderr must name. Every failing case
// must print exactly one line ("canopy-voxelize: error: <file>: <problem>"), exit with the
// documented code and leave no output (nor temporary file) behind.
#include <gtest/gtest.h>
#include <sys/stat.h>
#include <sys/wait.h>

#include <array>
#include <cstdio>
#include <cstring>
#include <dirent.h>
#include <limits>

#include "test_helpers.h"

using namespace canopy::test;

namespace {

const std::string kBin = std::string(CANOPY_BINARY_DIR) + "/bin/canopy-voxelize";
const std::string kShared = CANOPY_SHARED_DIR;

struct RunResult {
  int code = -1;
  std::string out, err;
};

RunResult run(const std::string& args, const std::string& dir) {
  const std::string errFile = dir + "/stderr.txt";
  // Under a time limit: a reader that loops forever (OpenMesh's PLY reader on a truncated header
  // did) fails the case with code 124 instead of stalling the suite.
  const std::string cmd = "timeout 120 " + kBin + " " + args + " 2>'" + errFile + "'";
  RunResult r;
  FILE* p = popen(cmd.c_str(), "r");
  if (!p) return r;
  std::array<char, 4096> buf;
  size_t n;
  while ((n = fread(buf.data(), 1, buf.size(), p)) > 0) r.out.append(buf.data(), n);
  const int status = pclose(p);
  r.code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  const auto e = readBytes(errFile);
  r.err.assign(e.begin(), e.end());
  std::remove(errFile.c_str());
  return r;
}

bool exists(const std::string& p) {
  struct stat st;
  return stat(p.c_str(), &st) == 0;
}

// Files in dir whose name contains "canopy-tmp" (atomic-output leftovers).
int leftovers(const std::string& dir) {
  int n = 0;
  if (DIR* d = opendir(dir.c_str())) {
    while (dirent* e = readdir(d)) n += std::strstr(e->d_name, "canopy-tmp") != nullptr;
    closedir(d);
  }
  return n;
}

int lines(const std::string& s) {
  int n = 0;
  for (char c : s) n += c == '\n';
  return n;
}

// Each test gets its own scratch directory (CTest may run them in parallel).
class VoxelizeCli : public ::testing::Test {
 protected:
  std::string dir;
  void SetUp() override {
    dir = scratchDir(std::string("voxelize_cli_") +
                     ::testing::UnitTest::GetInstance()->current_test_info()->name());
  }
};

std::vector<float> oneTriangle(float bad = 0.f, bool useBad = false) {
  std::vector<float> p = {0, 0, 0, 1, 0, 0, 0, 1, 0.5f};
  if (useBad) p[4] = bad;
  return p;
}

// The sample plant as a .gltf with its buffer in sample.bin and its leaf texture either in
// leaf.png (external) or inline as a data: URI (embedded). imageUri overrides the external name.
void writeSampleGltf(const std::string& dir, const std::string& name, bool embedded,
                     const std::string& imageUri = "leaf.png") {
  const auto glb = canopy::samplePlantGlb();
  uint32_t jsonLen, binLen;
  std::memcpy(&jsonLen, glb.data() + 12, 4);
  std::memcpy(&binLen, glb.data() + 20 + jsonLen, 4);
  auto doc = nlohmann::json::parse(std::string(glb.begin() + 20, glb.begin() + 20 + jsonLen));
  const std::vector<uint8_t> bin(glb.begin() + 28 + jsonLen, glb.begin() + 28 + jsonLen + binLen);
  auto& image = doc["images"][0];
  const auto& view = doc["bufferViews"][image["bufferView"].get<size_t>()];
  const size_t off = view["byteOffset"], len = view["byteLength"];
  const std::vector<uint8_t> png(bin.begin() + long(off), bin.begin() + long(off + len));
  image.erase("bufferView");
  image.erase("mimeType");
  if (embedded) {
    static const char* b64 = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    std::string enc;
    for (size_t i = 0; i < png.size(); i += 3) {
      const uint32_t v = uint32_t(png[i]) << 16 | (i + 1 < png.size() ? uint32_t(png[i + 1]) << 8 : 0) |
                         (i + 2 < png.size() ? png[i + 2] : 0);
      enc += b64[v >> 18 & 63];
      enc += b64[v >> 12 & 63];
      enc += i + 1 < png.size() ? b64[v >> 6 & 63] : '=';
      enc += i + 2 < png.size() ? b64[v & 63] : '=';
    }
    image["uri"] = "data:image/png;base64," + enc;
  } else {
    image["uri"] = imageUri;
    writeBytes(dir + "/leaf.png", png);
  }
  doc["buffers"][0]["uri"] = "sample.bin";
  writeBytes(dir + "/sample.bin", bin);
  writeText(dir + "/" + name, doc.dump());
}

// A binary STL of the given triangles (normals zero).
std::vector<uint8_t> binaryStl(const std::vector<std::array<float, 9>>& tris) {
  std::vector<uint8_t> b(84 + 50 * tris.size(), 0);  // 80-byte header, count, 50-byte facets
  const uint32_t n = uint32_t(tris.size());
  std::memcpy(b.data() + 80, &n, 4);
  for (size_t i = 0; i < tris.size(); ++i) std::memcpy(b.data() + 84 + 50 * i + 12, tris[i].data(), 36);  // after the normal
  return b;
}

// One triangle whose node has this glTF (column-major) matrix.
void writeNodeMatrixGltf(const std::string& path, const std::vector<double>& columnMajor) {
  GltfParts g = triangleGltf(oneTriangle(), {0, 1, 2});
  g.doc["nodes"][0]["matrix"] = columnMajor;
  writeBytes(path, toGlb(g));
}

}  // namespace

// ---- Bad input: (name, setup, args, expected code, text stderr must contain) -----------------
struct BadCase {
  std::string name;
  std::function<void(const std::string& dir)> make;
  std::string input;  // relative to dir, or absolute
  std::string extra;
  int code;
  std::string mustName;  // substring of the error line (the file)
};

TEST_F(VoxelizeCli, BadInputsFailCleanly) {
  const std::vector<BadCase> cases = {
      {"missing file", [](const std::string&) {}, "nope.glb", "", 2, "nope.glb"},
      {"directory", [](const std::string& d) { std::system(("mkdir -p '" + d + "/adir.glb'").c_str()); },
       "adir.glb", "", 2, "adir.glb"},
      {"empty glb", [](const std::string& d) { writeBytes(d + "/empty.glb", {}); }, "empty.glb", "", 3, "empty.glb"},
      {"empty obj", [](const std::string& d) { writeBytes(d + "/empty.obj", {}); }, "empty.obj", "", 3, "empty.obj"},
      {"truncated glb",
       [](const std::string& d) {
         auto b = canopy::samplePlantGlb();
         b.resize(b.size() / 2);
         writeBytes(d + "/trunc.glb", b);
       },
       "trunc.glb", "", 3, "trunc.glb"},
      {"gltf with missing buffer",
       [](const std::string& d) {
         GltfParts g = triangleGltf(oneTriangle(), {0, 1, 2});
         g.doc["buffers"][0]["uri"] = "missing.bin";
         writeText(d + "/nobuf.gltf", g.doc.dump());
       },
       "nobuf.gltf", "", 2, "nobuf.gltf"},
      {"gltf whose buffer is a FIFO (tinygltf would block reading it)",
       [](const std::string& d) {
         GltfParts g = triangleGltf(oneTriangle(), {0, 1, 2});
         g.doc["buffers"][0]["uri"] = "pipe.bin";
         writeText(d + "/fifo.gltf", g.doc.dump());
         ::mkfifo((d + "/pipe.bin").c_str(), 0600);
       },
       "fifo.gltf", "", 2, "pipe.bin : not a regular file)"},
      {"gltf with missing image",
       [](const std::string& d) { writeSampleGltf(d, "noimg.gltf", false, "missing.png"); }, "noimg.gltf", "", 2,
       "noimg.gltf"},
      {"NaN vertex",
       [](const std::string& d) {
         writeBytes(d + "/nan.glb", toGlb(triangleGltf(oneTriangle(std::numeric_limits<float>::quiet_NaN(), true), {0, 1, 2})));
       },
       "nan.glb", "", 3, "nan.glb"},
      {"inf vertex",
       [](const std::string& d) {
         writeBytes(d + "/inf.glb", toGlb(triangleGltf(oneTriangle(std::numeric_limits<float>::infinity(), true), {0, 1, 2})));
       },
       "inf.glb", "", 3, "inf.glb"},
      {"NaN vertex in OBJ", [](const std::string& d) { writeText(d + "/nan.obj", "v 0 0 0\nv 1 0 0\nv nan 1 0\nf 1 2 3\n"); },
       "nan.obj", "", 3, "nan.obj: vertex 3 has a NaN"},
      {"zero triangles",
       [](const std::string& d) { writeBytes(d + "/zero.glb", toGlb(triangleGltf(oneTriangle(), {}))); },
       "zero.glb", "", 3, "zero.glb"},
      {"only degenerate triangles",
       [](const std::string& d) { writeBytes(d + "/degen.glb", toGlb(triangleGltf({0, 0, 0, 1, 1, 1, 2, 2, 2}, {0, 1, 2}))); },
       "degen.glb", "", 3, "degen.glb"},
      {"index out of range",
       [](const std::string& d) { writeBytes(d + "/badidx.glb", toGlb(triangleGltf(oneTriangle(), {0, 1, 7}))); },
       "badidx.glb", "", 3, "badidx.glb"},
      {"unsupported required extension",
       [](const std::string& d) {
         GltfParts g = triangleGltf(oneTriangle(), {0, 1, 2});
         g.doc["extensionsRequired"] = {"EXT_meshopt_compression"};
         g.doc["extensionsUsed"] = {"EXT_meshopt_compression"};
         writeBytes(d + "/meshopt.glb", toGlb(g));
       },
       "meshopt.glb", "", 5, "EXT_meshopt_compression"},
      {"not a mesh format", [](const std::string& d) { writeText(d + "/notes.txt", "hello"); }, "notes.txt", "", 5, "notes.txt"},
      // A truncated PLY header made OpenMesh's reader loop forever printing "Unsupported entry type".
      {"truncated ASCII PLY header",
       [](const std::string& d) { writeText(d + "/t.ply", "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\n"); },
       "t.ply", "", 3, "t.ply: truncated PLY header"},
      {"binary PLY cut inside its header",
       [](const std::string& d) {
         writeText(d + "/tb.ply", "ply\nformat binary_little_endian 1.0\nelement vertex 3\nproperty float x\nprop");
       },
       "tb.ply", "", 3, "tb.ply: truncated PLY header"},
      {"NaN vertex in binary STL",
       [](const std::string& d) {
         const float nan = std::numeric_limits<float>::quiet_NaN();
         writeBytes(d + "/nanbin.stl", binaryStl({{0, 0, 0, 1, 0, 0, 0, 1, 0}, {0, 0, 0, 1, 0, 0, 0, nan, 0}}));
       },
       "nanbin.stl", "", 3, "nanbin.stl: triangle 1 has a NaN or infinite vertex coordinate"},
      {"NaN vertex in ASCII STL",
       [](const std::string& d) {
         writeText(d + "/nan.stl", "solid t\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1 0 0\nvertex 0 1 0\n"
                                   "endloop\nendfacet\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1 0 0\n"
                                   "vertex 0 nan 1\nendloop\nendfacet\nendsolid t\n");
       },
       "nan.stl", "", 3, "nan.stl: triangle 1 has a NaN or infinite vertex coordinate"},
      {"NaN vertex in ASCII PLY",
       [](const std::string& d) {
         writeText(d + "/nan.ply", "ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\n"
                                   "property float z\nelement face 2\nproperty list uchar int vertex_indices\nend_header\n"
                                   "0 0 0\n1 0 0\n0 1 0\n0 nan 1\n3 0 1 2\n3 0 1 3\n");
       },
       "nan.ply", "", 3, "nan.ply: triangle 1 has a NaN or infinite vertex coordinate"},
      {"NaN vertex in OFF",
       [](const std::string& d) { writeText(d + "/nan2.off", "OFF\n4 2 0\n0 0 0\n1 0 0\n0 1 0\n0 nan 1\n3 0 1 2\n3 0 1 3\n"); },
       "nan2.off", "", 3, "nan2.off: line 6: vertex 3 (counting from 0) has a NaN or infinite coordinate"},
      // OpenMesh's OFF reader (replaced by off_loader.cpp) reserved what the header declares (out
      // of memory, no file named), read truncated files as far as they went and dropped faces with
      // bad indices silently; its OBJ and STL readers still read truncated files and drop bad faces.
      {"OFF with absurd counts",
       [](const std::string& d) { writeText(d + "/big.off", "OFF\n4000000000 2000000000 0\n0 0 0\n"); }, "big.off", "", 3,
       "big.off: the OFF header declares 4000000000 vertices and 2000000000 faces, more than its 34 bytes can hold"},
      {"OFF with a negative count", [](const std::string& d) { writeText(d + "/neg.off", "OFF\n-3 1 0\n"); }, "neg.off", "", 3,
       "neg.off: line 2: bad OFF counts"},
      {"OFF cut inside its faces",
       [](const std::string& d) { writeText(d + "/cut.off", "OFF\n4 3 0\n0 0 0\n1 0 0\n0 1 0\n0 0 1\n3 0 1 2\n3 0 1 3\n"); },
       "cut.off", "", 3, "cut.off: truncated OFF file (2 of 3 faces;"},
      {"OFF face index out of range",
       [](const std::string& d) { writeText(d + "/idx.off", "OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 99\n"); }, "idx.off", "",
       3, "idx.off: line 6: face 0 (counting from 0) refers to vertex '99', but the file has 3 vertices"},
      {"OBJ face index out of range",
       [](const std::string& d) { writeText(d + "/idx.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\nf 1 2 99\n"); }, "idx.obj",
       "", 3, "idx.obj: line 5: face refers to vertex 99, but the file has 3 vertices"},
      {"OBJ relative index before the first vertex",
       [](const std::string& d) { writeText(d + "/rel.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf -1 -2 -4\n"); }, "rel.obj", "", 3,
       "rel.obj: line 4: face refers to vertex -4, but only 3 vertices precede it"},
      {"OBJ vertex index 0",
       [](const std::string& d) { writeText(d + "/zero.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 0 1 2\n"); }, "zero.obj", "", 3,
       "zero.obj: line 4: face refers to vertex 0"},
      {"binary STL cut short",
       [](const std::string& d) {
         auto b = binaryStl({{0, 0, 0, 1, 0, 0, 0, 1, 0}, {0, 0, 0, 1, 0, 0, 0, 0, 1}});
         b.resize(b.size() - 10);
         writeBytes(d + "/cut.stl", b);
       },
       "cut.stl", "", 3, "cut.stl: truncated or corrupt binary STL (its header declares 2 triangles, 184 bytes; the file has 174)"},
      {"ASCII STL cut short",
       [](const std::string& d) {
         writeText(d + "/cuta.stl", "solid t\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1 0 0\nvertex 0 1 0\n"
                                    "endloop\nendfacet\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\n");
       },
       "cuta.stl", "", 3, "cuta.stl: truncated ASCII STL (no 'endsolid' after its last facet)"},
      {"binary STL with a 'solid' header cut short",
       [](const std::string& d) {
         auto b = binaryStl({{0, 0, 0, 1, 0, 0, 0, 1, 0}, {0, 0, 0, 1, 0, 0, 0, 0, 1}});
         std::memcpy(b.data(), "solid exported", 14);
         b.resize(b.size() - 10);
         writeBytes(d + "/cutsolid.stl", b);
       },
       "cutsolid.stl", "", 3, "cutsolid.stl: truncated or corrupt binary STL (its header declares 2 triangles"},
      // Whole-scene voxelisation applies the node matrix rule that --instances applies.
      {"non-affine node matrix",
       [](const std::string& d) { writeNodeMatrixGltf(d + "/proj.glb", {1, 0, 0, 0.5, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1}); },
       "proj.glb", "", 3, "proj.glb: instances[0].matrix last row must be 0,0,0,1"},
      {"singular node matrix",
       [](const std::string& d) { writeNodeMatrixGltf(d + "/sing.glb", {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 0, 0, 0, 0, 0, 1}); },
       "sing.glb", "", 3, "sing.glb: instances[0].matrix is singular"},
      {"all-zero node matrix",
       [](const std::string& d) { writeNodeMatrixGltf(d + "/zero.glb", std::vector<double>(16, 0.0)); },
       "zero.glb", "", 3, "zero.glb: instances[0].matrix"},
      {"every triangle removed by the alpha test",
       [](const std::string& d) {
         GltfParts g = triangleGltf(oneTriangle(), {0, 1, 2});
         g.doc["materials"] = {{{"name", "leaves"}, {"alphaMode", "MASK"},
                                {"pbrMetallicRoughness", {{"baseColorFactor", {1.0, 1.0, 1.0, 0.0}}}}}};
         g.doc["meshes"][0]["primitives"][0]["material"] = 0;
         writeBytes(d + "/alpha0.glb", toGlb(g));
       },
       "alpha0.glb", "", 3, "alpha0.glb: no cell is occupied (all 1 triangles were removed by the alpha test)"},
      {"mesh -1", [](const std::string&) {}, kShared + "/assets/plants/bush_2.glb", "--mesh -1", 1, "--mesh"},
      {"mesh 99", [](const std::string&) {}, kShared + "/assets/plants/bush_2.glb", "--mesh 99", 1, "--mesh"},
      {"resolution above the reader's 2048", [](const std::string&) {}, kShared + "/assets/plants/bush_2.glb",
       "--resolution 2049 -s 1", 1, "--resolution 2049 is outside 8..2048"},
      {"resolution 0", [](const std::string&) {}, kShared + "/assets/plants/bush_2.glb", "--resolution 0", 1, "--resolution 0 is outside"},
      {"resolution absurd", [](const std::string&) {}, kShared + "/assets/plants/bush_2.glb", "--resolution 1000000", 1, "--resolution 1000000 is outside"},
      {"supersample absurd", [](const std::string&) {}, kShared + "/assets/plants/bush_2.glb", "--supersample 99", 1, "--supersample"},
      {"unwritable output", [](const std::string&) {}, kShared + "/assets/plants/bush_2.glb", "-o /nonexistent-dir/x.vdb", 2,
       "/nonexistent-dir/x.vdb"},
  };
  for (const BadCase& c : cases) {
    SCOPED_TRACE(c.name);
    c.make(dir);
    const std::string input = c.input[0] == '/' ? c.input : dir + "/" + c.input;
    const std::string out = dir + "/out.vdb";
    std::remove(out.c_str());
    const std::string outArg = c.extra.find("-o ") == std::string::npos ? " -o '" + out + "'" : "";
    // -r 16 unless the case sets the resolution (CLI11 refuses an option given twice, which
    // would pass a resolution case for the wrong reason).
    const std::string res = c.extra.find("--resolution") == std::string::npos ? " -r 16" : "";
    const RunResult r = run("'" + input + "' -q" + res + outArg + " " + c.extra, dir);
    EXPECT_EQ(r.code, c.code) << r.err;
    EXPECT_NE(r.err.find("canopy-voxelize: error: "), std::string::npos) << r.err;
    EXPECT_NE(r.err.find(c.mustName), std::string::npos) << r.err;
    // One line of error (usage errors carry the "see --help" hint on the same line).
    EXPECT_EQ(lines(r.err), 1) << r.err;
    EXPECT_FALSE(exists(out));
    EXPECT_EQ(leftovers(dir), 0);
  }
}

TEST_F(VoxelizeCli, OutputBytesAreIdenticalAcrossRuns) {
  const std::string glb = dir + "/det.glb";
  ASSERT_EQ(run("--write-sample '" + glb + "'", dir).code, 0);
  const auto sample1 = readBytes(glb);
  ASSERT_EQ(run("--write-sample '" + glb + "'", dir).code, 0);
  EXPECT_EQ(sample1, readBytes(glb)) << "the sample plant must be deterministic";
  ASSERT_EQ(run("'" + glb + "' -r 32 -o '" + dir + "/a.vdb'", dir).code, 0);
  ASSERT_EQ(run("'" + glb + "' -r 32 -o '" + dir + "/b.vdb'", dir).code, 0);
  const auto a = readBytes(dir + "/a.vdb"), b = readBytes(dir + "/b.vdb");
  ASSERT_GT(a.size(), 100u);
  EXPECT_EQ(a, b);
}

// The same plant as .glb (image in the binary chunk), .gltf + external .png, and .gltf with a
// data: URI image gives the same lattice.
TEST_F(VoxelizeCli, EmbeddedAndExternalImagesGiveTheSameLattice) {
  writeBytes(dir + "/img.glb", canopy::samplePlantGlb());
  writeSampleGltf(dir, "external.gltf", false);
  writeSampleGltf(dir, "embedded.gltf", true);
  double density[3];
  const char* names[3] = {"img.glb", "external.gltf", "embedded.gltf"};
  for (int i = 0; i < 3; ++i) {
    const RunResult r = run("'" + dir + "/" + names[i] + "' -q -r 24 -o '" + dir + "/img.vdb' --json", dir);
    ASSERT_EQ(r.code, 0) << names[i] << ": " << r.err;
    const auto j = nlohmann::json::parse(r.out);
    density[i] = j["total_density"];
    EXPECT_GT(j["alpha_rejected"].get<int>(), 0) << names[i];
  }
  EXPECT_EQ(density[0], density[1]);
  EXPECT_EQ(density[0], density[2]);
}

// A .gltf's external buffer and image are inputs of the run: an output path naming one of them
// (or the .gltf) is refused with a usage error and the file keeps its bytes.
TEST_F(VoxelizeCli, OutputNamingAnExternalBufferOrImageIsRefused) {
  writeSampleGltf(dir, "external.gltf", false);
  for (const char* name : {"external.gltf", "sample.bin", "leaf.png"}) {
    SCOPED_TRACE(name);
    const std::string path = dir + "/" + name;
    const auto before = readBytes(path);
    const RunResult r = run("'" + dir + "/external.gltf' -q -r 16 -o '" + path + "'", dir);
    EXPECT_EQ(r.code, 1) << r.err;
    EXPECT_NE(r.err.find(path + ": output path is the same file as an input"), std::string::npos) << r.err;
    EXPECT_EQ(lines(r.err), 1) << r.err;
    EXPECT_EQ(readBytes(path), before);
    EXPECT_EQ(leftovers(dir), 0);
  }
}

TEST_F(VoxelizeCli, JsonReportAndInfo) {
  const std::string glb = dir + "/rep.glb", vdb = dir + "/rep.vdb";
  ASSERT_EQ(run("--write-sample '" + glb + "'", dir).code, 0);
  const RunResult r = run("'" + glb + "' -r 32 -s 4 -o '" + vdb + "' --json", dir);
  ASSERT_EQ(r.code, 0) << r.err;
  const auto j = nlohmann::json::parse(r.out);
  EXPECT_EQ(j["tool"], "canopy-voxelize");
  EXPECT_EQ(j["exit_code"], 0);
  EXPECT_EQ(j["resolution"], 32);
  EXPECT_EQ(j["supersample"], 4);
  EXPECT_GT(j["occupied_cells"].get<int>(), 10);
  EXPECT_GT(j["total_density"].get<double>(), 0.0);
  EXPECT_GT(j["wood_fraction"].get<double>(), 0.0);
  EXPECT_LT(j["wood_fraction"].get<double>(), 1.0);
  EXPECT_GT(j["triangles"]["alpha_tested"].get<int>(), 0);
  EXPECT_GT(j["alpha_rejected"].get<int>(), 0);
  EXPECT_EQ(j["lattice_max"][0], 31);
  EXPECT_GT(j["voxel_size"].get<double>(), 0.0);
  EXPECT_NE(j["source"].get<std::string>().find("xxh64:"), std::string::npos);

  const RunResult info = run("info '" + vdb + "' --json", dir);
  ASSERT_EQ(info.code, 0) << info.err;
  const auto k = nlohmann::json::parse(info.out);
  EXPECT_EQ(k["occupied_cells"], j["occupied_cells"]);
  EXPECT_NEAR(k["total_density"].get<double>(), j["total_density"].get<double>(), 1e-3);
  EXPECT_NEAR(k["wood_fraction"].get<double>(), j["wood_fraction"].get<double>(), 1e-6);
  EXPECT_EQ(k["lattice_size"][0], 32);
  EXPECT_EQ(k["metadata"]["canopy_supersample"], "4");
  EXPECT_EQ(k["grids"].size(), 3u);
}

TEST_F(VoxelizeCli, InfoRejectsFilesThatAreNotLattices) {
  writeText(dir + "/text.vdb", "not a vdb at all");
  RunResult r = run("info '" + dir + "/text.vdb'", dir);
  EXPECT_EQ(r.code, 3);
  // The prefix every canopy-voxelize error has (not "canopy-voxelize info: error:").
  EXPECT_EQ(r.err.rfind("canopy-voxelize: error: " + dir + "/text.vdb: ", 0), 0u) << r.err;
  r = run("info '" + dir + "/missing.vdb'", dir);
  EXPECT_EQ(r.code, 2);
  r = run("info", dir);  // a usage error points at the subcommand's help
  EXPECT_EQ(r.code, 1);
  EXPECT_EQ(r.err.rfind("canopy-voxelize: error: ", 0), 0u) << r.err;
  EXPECT_NE(r.err.find("(see canopy-voxelize info --help)"), std::string::npos) << r.err;
  // A truncated lattice.
  const std::string glb = dir + "/t.glb", vdb = dir + "/t.vdb";
  ASSERT_EQ(run("--write-sample '" + glb + "'", dir).code, 0);
  ASSERT_EQ(run("'" + glb + "' -r 16 -o '" + vdb + "'", dir).code, 0);
  auto bytes = readBytes(vdb);
  bytes.resize(bytes.size() - 20);
  writeBytes(dir + "/cut.vdb", bytes);
  r = run("info '" + dir + "/cut.vdb'", dir);
  EXPECT_EQ(r.code, 3);
  EXPECT_EQ(lines(r.err), 1) << r.err;
}

TEST_F(VoxelizeCli, SceneInstanceList) {
  const std::string json = dir + "/grove.scene.json";
  const RunResult r = run("'" + kShared + "/assets/scenes/grove.glb' --instances '" + json +
                        "' --model-pattern 'grove.{name}.density.vdb'", dir);
  ASSERT_EQ(r.code, 0) << r.err;
  std::ifstream f(json);
  const auto j = nlohmann::json::parse(f);
  EXPECT_EQ(j["canopy_scene"], 1);
  ASSERT_EQ(j["models"].size(), 3u);
  ASSERT_EQ(j["instances"].size(), 12u);
  EXPECT_EQ(j["models"][0]["density"], "grove.Oak_Medium.density.vdb");
  EXPECT_NE(j["source"].get<std::string>().find("grove.glb xxh64:"), std::string::npos);
  for (int m = 0; m < 3; ++m) EXPECT_EQ(j["models"][size_t(m)]["mesh"], m);  // grove's meshes 0, 1, 2
  for (const auto& inst : j["instances"]) {
    EXPECT_TRUE(inst["node"].is_string());
    ASSERT_EQ(inst["matrix"].size(), 16u);
    EXPECT_EQ(inst["matrix"][15], 1.0);
    EXPECT_EQ(inst["matrix"][12], 0.0);
    EXPECT_LT(inst["model"].get<int>(), 3);
  }
}

// The instance list passes the scene list's checks (formats/scene_json.h checkScene): a node that
// scales its mesh to nothing is refused, and no list is written.
TEST_F(VoxelizeCli, SceneInstanceListRefusesASingularNode) {
  GltfParts g = triangleGltf(oneTriangle(), {0, 1, 2});
  g.doc["nodes"][0]["scale"] = {1.0, 0.0, 1.0};
  writeBytes(dir + "/flat.glb", toGlb(g));
  const RunResult r = run("'" + dir + "/flat.glb' --instances '" + dir + "/flat.scene.json'", dir);
  EXPECT_EQ(r.code, 3);
  EXPECT_NE(r.err.find("flat.glb: instances[0].matrix is singular"), std::string::npos) << r.err;
  EXPECT_EQ(lines(r.err), 1) << r.err;
  EXPECT_FALSE(std::ifstream(dir + "/flat.scene.json").good());
}

TEST_F(VoxelizeCli, HelpVersionAndUsage) {
  EXPECT_EQ(run("--help", dir).code, 0);
  const RunResult v = run("--version", dir);
  EXPECT_EQ(v.code, 0);
  EXPECT_NE(v.out.find("canopy-voxelize"), std::string::npos);
  EXPECT_EQ(run("", dir).code, 1);
  EXPECT_EQ(run("--bogus-flag", dir).code, 1);
  EXPECT_EQ(run("'" + kShared + "/assets/plants/bush_2.glb' --device cuda -o '" + dir + "/x.vdb'", dir).code, 5);
}

// ---- --detail ------------------------------------------------------------------------------------

namespace {

// The .vdb files in dir (what a run left behind).
std::vector<std::string> vdbFiles(const std::string& dir) {
  std::vector<std::string> names;
  if (DIR* d = opendir(dir.c_str())) {
    while (dirent* e = readdir(d)) {
      const std::string n = e->d_name;
      if (n.size() > 4 && n.compare(n.size() - 4, 4, ".vdb") == 0) names.push_back(n);
    }
    closedir(d);
  }
  return names;
}

}  // namespace

// The lattice written with --detail is byte for byte the one written without it; the detail
// lattice lands beside it (.density.vdb -> .detail.vdb, or --detail-output), with the same bytes on
// every run, and `info` shows the lattice it nests in.
TEST_F(VoxelizeCli, DetailLeavesTheLatticeByteIdentical) {
  const std::string glb = dir + "/plant.glb";
  ASSERT_EQ(run("--write-sample '" + glb + "'", dir).code, 0);
  ASSERT_EQ(run("'" + glb + "' -q -r 16 -s 8 -o '" + dir + "/plain.density.vdb'", dir).code, 0);
  const RunResult r = run("'" + glb + "' -q -r 16 -s 8 --detail 64 -o '" + dir + "/plant.density.vdb' --json", dir);
  ASSERT_EQ(r.code, 0) << r.err;
  const auto plain = readBytes(dir + "/plain.density.vdb");
  ASSERT_GT(plain.size(), 100u);
  EXPECT_EQ(readBytes(dir + "/plant.density.vdb"), plain);
  const auto detail = readBytes(dir + "/plant.detail.vdb");
  ASSERT_GT(detail.size(), 100u);

  const auto j = nlohmann::json::parse(r.out);
  EXPECT_EQ(j["resolution"], 16);
  EXPECT_EQ(j["supersample"], 8);
  ASSERT_TRUE(j["detail"].is_object());
  EXPECT_EQ(j["detail"]["resolution"], 64);
  EXPECT_EQ(j["detail"]["factor"], 4);
  EXPECT_EQ(j["detail"]["supersample"], 2);
  EXPECT_EQ(j["detail"]["output"], dir + "/plant.detail.vdb");
  EXPECT_GT(j["detail"]["occupied_cells"].get<int>(), j["occupied_cells"].get<int>());
  // Each detail cell is 1/64 of a lattice cell: 64 x the total density.
  EXPECT_NEAR(j["detail"]["total_density"].get<double>(), 64 * j["total_density"].get<double>(),
              1e-6 * j["detail"]["total_density"].get<double>());
  const RunResult none = run("'" + glb + "' -q -r 16 -o '" + dir + "/none.vdb' --json", dir);
  EXPECT_TRUE(nlohmann::json::parse(none.out)["detail"].is_null());

  // Same bytes again, through --detail-output and with one thread's worth of work split differently.
  const RunResult again = run("'" + glb + "' -q -r 16 -s 8 --detail 64 -o '" + dir + "/again.density.vdb' --detail-output '" +
                                  dir + "/again.fine.vdb'",
                              dir);
  ASSERT_EQ(again.code, 0) << again.err;
  EXPECT_EQ(readBytes(dir + "/again.fine.vdb"), detail);
  EXPECT_FALSE(exists(dir + "/again.detail.vdb"));

  const RunResult info = run("info '" + dir + "/plant.detail.vdb' --json", dir);
  ASSERT_EQ(info.code, 0) << info.err;
  const auto k = nlohmann::json::parse(info.out);
  EXPECT_EQ(k["lattice_size"][0], 64);
  EXPECT_EQ(k["detail_factor"], 4);
  EXPECT_EQ(k["light_lattice_min"], nlohmann::json({0, 0, 0}));
  EXPECT_EQ(k["light_lattice_max"], nlohmann::json({15, 15, 15}));
  EXPECT_EQ(k["occupied_cells"], j["detail"]["occupied_cells"]);
  EXPECT_EQ(k["metadata"]["canopy_resolution"], "64");
  EXPECT_EQ(k["metadata"]["canopy_supersample"], "2");
  EXPECT_EQ(k["metadata"]["canopy_light_resolution"], "16");
  EXPECT_NEAR(std::stod(k["metadata"]["canopy_voxel_size"].get<std::string>()), j["voxel_size"].get<double>() / 4, 1e-6);
  EXPECT_EQ(k["source"], j["source"]);
  const RunResult text = run("info '" + dir + "/plant.detail.vdb'", dir);
  ASSERT_EQ(text.code, 0) << text.err;
  EXPECT_NE(text.out.find("detail of      light lattice (0,0,0)..(15,15,15), 4 x 4 x 4 cells per light cell"),
            std::string::npos)
      << text.out;
  // An ordinary lattice: factor 1 and nothing more.
  const auto plainInfo = nlohmann::json::parse(run("info '" + dir + "/plain.density.vdb' --json", dir).out);
  EXPECT_EQ(plainInfo["detail_factor"], 1);
  EXPECT_FALSE(plainInfo.contains("light_lattice_min"));
  EXPECT_EQ(run("info '" + dir + "/plain.density.vdb'", dir).out.find("detail of"), std::string::npos);
}

// Without -s, --detail takes supersample max(8, k): k = 16 gives 16 (one sub-cell per detail cell).
TEST_F(VoxelizeCli, DetailDefaultSupersample) {
  const std::string glb = dir + "/plant.glb";
  ASSERT_EQ(run("--write-sample '" + glb + "'", dir).code, 0);
  RunResult r = run("'" + glb + "' -q -r 8 --detail 128 -o '" + dir + "/a.density.vdb' --json", dir);
  ASSERT_EQ(r.code, 0) << r.err;
  auto j = nlohmann::json::parse(r.out);
  EXPECT_EQ(j["supersample"], 16);
  EXPECT_EQ(j["detail"]["supersample"], 1);
  r = run("'" + glb + "' -q -r 8 --detail 16 -o '" + dir + "/b.density.vdb' --json", dir);
  ASSERT_EQ(r.code, 0) << r.err;
  j = nlohmann::json::parse(r.out);
  EXPECT_EQ(j["supersample"], 8);
  EXPECT_EQ(j["detail"]["supersample"], 4);
}

// Every refused combination exits 1 with one line naming the option and writes no file; a lattice
// whose write fails after the detail lattice's (here: -o names the input) takes the detail with it.
TEST_F(VoxelizeCli, DetailUsageErrorsWriteNothing) {
  const std::string glb = dir + "/plant.glb";
  ASSERT_EQ(run("--write-sample '" + glb + "'", dir).code, 0);
  const std::string in = "'" + glb + "' -q ", out = " -o '" + dir + "/p.density.vdb'";
  const std::vector<std::pair<std::string, std::string>> cases = {
      {"-r 16 --detail 16" + out, "--detail 16 is not finer than --resolution 16"},
      {"-r 16 --detail 8" + out, "--detail 8 is not finer than --resolution 16"},
      {"-r 16 --detail 0" + out, "--detail 0 is not finer than --resolution 16"},
      {"-r 16 --detail 48" + out, "--detail 48 is not --resolution 16 times 2, 4, 8 or 16"},
      {"-r 16 --detail 512" + out, "--detail 512 is not --resolution 16 times 2, 4, 8 or 16"},
      {"-r 256 --detail 4096" + out, "--detail 4096 exceeds 2048 cells per axis"},
      {"-r 16 -s 4 --detail 128" + out, "--supersample 4 must be a multiple of the detail factor 8"},
      {"-r 16 -s 8 --detail 256" + out, "--supersample 8 must be a multiple of the detail factor 16"},
      {"-r 16 --detail 32 -o '" + dir + "/p.vdb'", "--detail needs --detail-output FILE when -o"},
      {"-r 16 --detail-output '" + dir + "/d.vdb'" + out, "--detail-output needs --detail"},
      {"-r 16 --detail 32 --detail-output '" + dir + "/p.density.vdb'" + out, "is the -o file"},
      {"-r 16 --detail 32 --instances '" + dir + "/p.scene.json'", "--detail needs -o"},
      {"-r 16 --detail 32 -o '" + glb + "' --detail-output '" + dir + "/d.vdb'",
       glb + ": output path is the same file as an input"},
  };
  const auto sample = readBytes(glb);
  for (const auto& [args, message] : cases) {
    SCOPED_TRACE(args);
    const RunResult r = run(in + args, dir);
    EXPECT_EQ(r.code, 1) << r.err;
    EXPECT_EQ(r.err.rfind("canopy-voxelize: error: ", 0), 0u) << r.err;
    EXPECT_NE(r.err.find(message), std::string::npos) << r.err;
    EXPECT_EQ(lines(r.err), 1) << r.err;
    EXPECT_EQ(vdbFiles(dir), std::vector<std::string>());
    EXPECT_FALSE(exists(dir + "/p.scene.json"));
    EXPECT_EQ(leftovers(dir), 0);
  }
  EXPECT_EQ(readBytes(glb), sample);
}
