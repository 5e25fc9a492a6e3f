// Core utilities: hashes, atomic outputs, --device parsing, deterministic VDB bytes, the
// shared-exponent RGB codec.
#include <gtest/gtest.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <csignal>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <functional>
#include <limits>
#include <random>
#include <thread>

#include "canopy/atomic_file.h"
#include "canopy/device.h"
#include "canopy/hash.h"
#include "canopy/rgb9e5.h"
#include "formats/lattice_vdb.h"

namespace fs = std::filesystem;

namespace {
// One directory per test process (CTest runs each test in its own), removed when the process's
// tests end, whatever each test left in it.
fs::path tempDirPath() { return fs::temp_directory_path() / ("canopy_core_" + std::to_string(getpid())); }
fs::path tempDir() {
  fs::path d = tempDirPath();
  fs::create_directories(d);
  return d;
}
class RemoveTempDir : public ::testing::Environment {
 public:
  void TearDown() override {
    std::error_code ec;
    fs::remove_all(tempDirPath(), ec);
  }
};
[[maybe_unused]] ::testing::Environment* const kRemoveTempDir = ::testing::AddGlobalTestEnvironment(new RemoveTempDir);
std::string slurp(const fs::path& p) {
  std::ifstream f(p, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(f), {});
}
}  // namespace

// RGB9E5 (canopy/rgb9e5.h): known words, clamping, the error bound over 1e-9..6e4, and canonical
// words surviving decode + encode.
TEST(Rgb9e5, KnownWordsAndClamping) {
  using canopy::rgb9e5Encode;
  float v[3];
  EXPECT_EQ(rgb9e5Encode(0.0f, 0.0f, 0.0f), 0u);
  EXPECT_EQ(rgb9e5Encode(1.0f, 1.0f, 1.0f), (16u << 27) | 256u | (256u << 9) | (256u << 18));
  canopy::rgb9e5Decode(rgb9e5Encode(1.0f, 0.5f, 0.25f), v);
  EXPECT_EQ(v[0], 1.0f);
  EXPECT_EQ(v[1], 0.5f);
  EXPECT_EQ(v[2], 0.25f);
  const float nan = std::numeric_limits<float>::quiet_NaN(), inf = std::numeric_limits<float>::infinity();
  canopy::rgb9e5Decode(rgb9e5Encode(nan, -1.0f, inf), v);
  EXPECT_EQ(v[0], 0.0f);
  EXPECT_EQ(v[1], 0.0f);
  EXPECT_EQ(v[2], canopy::kRgb9e5Max);
  canopy::rgb9e5Decode(rgb9e5Encode(1e30f, 0.0f, -inf), v);
  EXPECT_EQ(v[0], 65408.0f);
  EXPECT_EQ(v[2], 0.0f);
  EXPECT_EQ(rgb9e5Encode(511.5f / 512.0f, 0.0f, 0.0f) >> 27, 16u);  // rounds up to 2^9: the next exponent
  canopy::rgb9e5Decode(0xFFFFFFFFu, v);                              // every word is finite
  EXPECT_EQ(v[0], canopy::kRgb9e5Max);
}

// The decode builds each channel from float bits (no integer conversion): every exponent and every
// mantissa of every channel gives exactly mantissa x 2^(e - 24), the format's definition.
TEST(Rgb9e5, DecodeIsTheMantissaTimesThePowerOfTwo) {
  for (uint32_t e = 0; e < 32; ++e)
    for (uint32_t m = 0; m < 512; ++m)
      for (uint32_t c = 0; c < 3; ++c) {
        const uint32_t other = (m * 7u + 3u) & 511u;  // the other channels vary too
        const uint32_t w = e << 27 | m << (9 * c) | other << (9 * ((c + 1) % 3));
        float v[3];
        canopy::rgb9e5Decode(w, v);
        ASSERT_EQ(v[c], std::ldexp(float(m), int(e) - 24)) << e << " " << m << " " << c;
        ASSERT_EQ(v[(c + 1) % 3], std::ldexp(float(other), int(e) - 24)) << e << " " << m << " " << c;
        ASSERT_EQ(v[(c + 2) % 3], 0.0f);
        ASSERT_FALSE(std::signbit(v[(c + 2) % 3]));
      }
}

TEST(Rgb9e5, ErrorIsWithinAHalfUnitOfTheLargestChannel) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> logScale(-9.0, 4.8), spread(-3.0, 0.0);
  for (int n = 0; n < 200000; ++n) {
    const double s = std::pow(10.0, logScale(rng));
    const float in[3] = {float(s * std::pow(10.0, spread(rng))), float(s * std::pow(10.0, spread(rng))), float(s)};
    float out[3];
    canopy::rgb9e5Decode(canopy::rgb9e5Encode(in[0], in[1], in[2]), out);
    const double bound = std::max(double(in[2]) / 511.0, std::ldexp(1.0, -25));
    for (int c = 0; c < 3; ++c) ASSERT_LE(std::abs(double(out[c]) - in[c]), bound) << in[0] << " " << in[1] << " " << in[2];
  }
  // A canonical word (the largest mantissa >= 256, or exponent 0) is its own encoding.
  for (int n = 0; n < 200000; ++n) {
    const uint32_t w = uint32_t(rng());
    const uint32_t e = w >> 27, m = std::max({w & 511u, (w >> 9) & 511u, (w >> 18) & 511u});
    if (e != 0 && m < 256) continue;
    float v[3];
    canopy::rgb9e5Decode(w, v);
    ASSERT_EQ(canopy::rgb9e5Encode(v[0], v[1], v[2]), w) << std::hex << w;
  }
}

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

namespace {
canopy::ExitCode errorCode(const std::function<void()>& f) {
  try {
    f();
  } catch (const canopy::Error& e) {
    return e.code();
  }
  return canopy::ExitCode::Ok;
}
size_t entries(const fs::path& d) {
  size_t n = 0;
  for (auto it = fs::directory_iterator(d); it != fs::directory_iterator(); ++it) ++n;
  return n;
}
}  // namespace

TEST(AtomicOutput, FollowsSymbolicLinksAndKeepsThem) {
  fs::path d = tempDir() / "links";
  fs::create_directories(d / "real");
  fs::create_symlink("real/target.bin", d / "link.bin");  // dangling until written
  canopy::writeFileAtomic((d / "link.bin").string(), std::string("one"));
  EXPECT_TRUE(fs::is_symlink(d / "link.bin"));
  EXPECT_EQ(slurp(d / "real" / "target.bin"), "one");
  canopy::writeFileAtomic((d / "link.bin").string(), std::string("two"));  // existing target replaced
  EXPECT_TRUE(fs::is_symlink(d / "link.bin"));
  EXPECT_EQ(slurp(d / "real" / "target.bin"), "two");
  EXPECT_EQ(entries(d / "real"), 1u);
  fs::remove_all(d);
}

TEST(AtomicOutput, WritesThroughAFifoInsteadOfReplacingIt) {
  fs::path d = tempDir() / "fifo";
  fs::create_directories(d);
  const fs::path fifo = d / "pipe";
  ASSERT_EQ(mkfifo(fifo.c_str(), 0600), 0);
  std::string got;
  std::thread reader([&] { got = slurp(fifo); });  // opening blocks until the writer opens
  canopy::writeFileAtomic(fifo.string(), std::string(3 << 20, 'x'));  // more than a pipe buffer
  reader.join();
  EXPECT_EQ(got.size(), size_t(3 << 20));
  EXPECT_TRUE(fs::is_fifo(fifo));
  EXPECT_EQ(entries(d), 1u);
  fs::remove_all(d);
}

TEST(AtomicOutput, InsideAToolRunAnInputIsNeverReplaced) {
  fs::path d = tempDir() / "inputs";
  fs::create_directories(d);
  const fs::path in = d / "in.vdb";
  canopy::writeFileAtomic(in.string(), std::string("input"));
  {
    canopy::InputTracking run;
    // reserved before the input is read, committed after: refused at commit
    EXPECT_EQ(errorCode([&] {
                canopy::AtomicOutput out(in.string());
                std::ofstream(out.tempPath()) << "output";
                (void)canopy::readFile(in.string());
                out.commit();
              }),
              canopy::ExitCode::Usage);
    EXPECT_EQ(slurp(in), "input");
    // read first: refused at once, also through another spelling of the path and a link
    EXPECT_EQ(errorCode([&] { canopy::writeFileAtomic(in.string(), std::string("x")); }), canopy::ExitCode::Usage);
    EXPECT_EQ(errorCode([&] { canopy::writeFileAtomic((d / "." / "in.vdb").string(), std::string("x")); }), canopy::ExitCode::Usage);
    fs::create_symlink("in.vdb", d / "alias.vdb");
    EXPECT_EQ(errorCode([&] { canopy::writeFileAtomic((d / "alias.vdb").string(), std::string("x")); }), canopy::ExitCode::Usage);
    EXPECT_EQ(slurp(in), "input");
    // one output file given twice in a run; a reservation that is never committed (an early
    // writability check, alive while the real output is written) does not count
    {
      canopy::AtomicOutput probe((d / "a.out").string());
      canopy::writeFileAtomic((d / "a.out").string(), std::string("a"));
    }
    // reserved before another output to the same file commits: refused at its own commit
    EXPECT_EQ(errorCode([&] {
                canopy::AtomicOutput late((d / "c.out").string());
                std::ofstream(late.tempPath()) << "late";
                canopy::writeFileAtomic((d / "." / "c.out").string(), std::string("c"));
                late.commit();
              }),
              canopy::ExitCode::Usage);
    EXPECT_EQ(slurp(d / "c.out"), "c");
    EXPECT_EQ(errorCode([&] { canopy::writeFileAtomic((d / "." / "a.out").string(), std::string("b")); }), canopy::ExitCode::Usage);
    EXPECT_EQ(slurp(d / "a.out"), "a");
  }
  // outside a tool's run (library use, tests) nothing is tracked
  canopy::writeFileAtomic(in.string(), std::string("rewritten"));
  EXPECT_EQ(slurp(in), "rewritten");
  EXPECT_EQ(entries(d), 4u);  // in.vdb, alias.vdb, a.out, c.out: no temporary left
  fs::remove_all(d);
}

TEST(AtomicOutput, ATerminatingSignalRemovesTheTemporary) {
  fs::path d = tempDir() / "signal";
  fs::create_directories(d);
  for (int sig : {SIGTERM, SIGINT, SIGHUP}) {
    const pid_t child = fork();
    ASSERT_GE(child, 0);
    if (child == 0) {
      canopy::AtomicOutput out((d / "out.bin").string());
      std::ofstream(out.tempPath()) << "partial";
      raise(sig);
      _exit(0);  // not reached
    }
    int status = 0;
    ASSERT_EQ(waitpid(child, &status, 0), child);
    EXPECT_TRUE(WIFSIGNALED(status) && WTERMSIG(status) == sig) << "signal " << sig << ", status " << status;
    EXPECT_EQ(entries(d), 0u) << "signal " << sig;
  }
  fs::remove_all(d);
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
