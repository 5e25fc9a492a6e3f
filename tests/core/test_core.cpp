// Core utilities: hashes, atomic outputs, --device parsing, deterministic VDB bytes.
#include <gtest/gtest.h>
#include <unistd.h>

#include <cstdio>
#include <filesystem>
#include <fstream>

#include "canopy/atomic_file.h"
#include "canopy/device.h"
#include "canopy/hash.h"
#include "formats/lattice_vdb.h"

namespace fs = std::filesystem;

namespace {
fs::path tempDir() {
  fs::path d = fs::temp_directory_path() / ("canopy_core_" + std::to_string(getpid()));
  fs::create_directories(d);
  return d;
}
std::string slurp(const fs::path& p) {
  std::ifstream f(p, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(f), {});
}
}  // namespace

TEST(Hash, Xxh64KnownVectors) {
  EXPECT_EQ(canopy::hash64("", 0), 0xEF46DB3751D8E999ULL);
  EXPECT_EQ(canopy::hash64("a", 1), 0xD24EC4F1A98C6E5BULL);
  EXPECT_EQ(canopy::hash64("abc", 3), 0x44BC2CF5AD770999ULL);
  std::string longer(1000, 'x');
  canopy::Hasher h;  // streaming in odd pieces equals one shot
  for (size_t i = 0; i < longer.size(); i += 7) h.update(longer.data() + i, std::min<size_t>(7, longer.size() - i));
  EXPECT_EQ(h.digest(), canopy::hash64(longer.data(), longer.size()));
}

TEST(Hash, Crc32KnownVector) {
  EXPECT_EQ(canopy::crc32(0, "123456789", 9), 0xCBF43926u);
  EXPECT_EQ(canopy::crc32(canopy::crc32(0, "1234", 4), "56789", 5), 0xCBF43926u);
}

TEST(AtomicOutput, CommitRenamesAndAbortLeavesNothing) {
  fs::path d = tempDir();
  fs::path target = d / "out.bin";
  {
    canopy::AtomicOutput out(target.string());
    std::ofstream(out.tempPath()) << "half";
    // no commit: destructor removes the temporary
  }
  EXPECT_FALSE(fs::exists(target));
  for (auto& e : fs::directory_iterator(d)) ADD_FAILURE() << "left behind: " << e.path();
  canopy::writeFileAtomic(target.string(), std::string("whole"));
  EXPECT_EQ(slurp(target), "whole");
  fs::remove_all(d);
}

TEST(AtomicOutput, UnwritableDirectoryFailsEarlyWithIoError) {
  try {
    canopy::AtomicOutput out("/nonexistent-dir/x.vdb");
    FAIL() << "expected an error";
  } catch (const canopy::Error& e) {
    EXPECT_EQ(e.code(), canopy::ExitCode::Io);
    EXPECT_NE(std::string(e.what()).find("/nonexistent-dir/x.vdb"), std::string::npos);
  }
}

TEST(Device, Parsing) {
  EXPECT_FALSE(canopy::resolveDevice("cpu").isCuda());
  EXPECT_EQ(canopy::resolveDevice("auto").isCuda(), canopy::cudaDeviceCount() > 0);
  EXPECT_THROW(canopy::resolveDevice("gpu"), canopy::Error);
  if (canopy::cudaDeviceCount() == 0) {
    try {
      canopy::resolveDevice("cuda");
      FAIL();
    } catch (const canopy::Error& e) {
      EXPECT_EQ(e.code(), canopy::ExitCode::Unsupported);
    }
  }
}

TEST(VdbIo, SameGridsGiveIdenticalBytesAndReadBack) {
  canopy::vdbio::initialize();
  fs::path d = tempDir();
  auto make = [] {
    auto g = openvdb::FloatGrid::create(0.0f);
    g->setName("density");
    auto acc = g->getAccessor();
    for (int i = 1; i < 20; ++i) acc.setValue(openvdb::Coord(i, 2 * i % 7, 3), 0.05f * i);
    canopy::vdbio::LatticeMeta m;
    m.min = openvdb::Coord(0);
    m.max = openvdb::Coord(21);
    m.source = "test";
    canopy::vdbio::stampGrid(*g, m);
    return g;
  };
  canopy::vdbio::writeVdb((d / "a.vdb").string(), {make()});
  canopy::vdbio::writeVdb((d / "b.vdb").string(), {make()});
  EXPECT_EQ(slurp(d / "a.vdb"), slurp(d / "b.vdb"));
  auto f = canopy::vdbio::readVdb((d / "a.vdb").string());
  auto g = f.require<openvdb::FloatGrid>("density");
  EXPECT_FLOAT_EQ(g->tree().getValue(openvdb::Coord(3, 6, 3)), 0.15f);
  auto m = canopy::vdbio::readLatticeMeta(*g, f.path);
  EXPECT_EQ(m.max, openvdb::Coord(21));
  EXPECT_THROW(f.require<openvdb::Vec3SGrid>("density"), canopy::Error);
  EXPECT_THROW(f.require<openvdb::FloatGrid>("wood"), canopy::Error);
  // Truncated copies are rejected with InvalidInput, never a crash.
  std::string bytes = slurp(d / "a.vdb");
  for (size_t len : {size_t(0), size_t(10), size_t(40), bytes.size() / 2, bytes.size() - 1}) {
    std::ofstream(d / "t.vdb", std::ios::binary).write(bytes.data(), std::streamsize(len));
    EXPECT_THROW(canopy::vdbio::readVdb((d / "t.vdb").string()), canopy::Error) << len;
  }
  // A flipped byte anywhere (past the magic) is caught by the content UUID.
  for (size_t at : {size_t(12), size_t(60), bytes.size() / 3, bytes.size() - 2}) {
    std::string bad = bytes;
    bad[at] = char(bad[at] ^ 0x20);
    std::ofstream(d / "t.vdb", std::ios::binary).write(bad.data(), std::streamsize(bad.size()));
    EXPECT_THROW(canopy::vdbio::readVdb((d / "t.vdb").string()), canopy::Error) << at;
  }
  fs::remove_all(d);
}
