// lattice_vdb.cpp: see lattice_vdb.h.
#include "formats/lattice_vdb.h"

#include <cstdio>
#include <cstring>
#include <fstream>
#include <mutex>

#include "canopy/atomic_file.h"
#include "canopy/cli.h"
#include "canopy/hash.h"

namespace canopy::vdbio {
namespace {
// OpenVDB file header (io/Archive.cc, writeHeader): magic i64, file version u32, library major u32,
// minor u32, hasGridOffsets u8, then the UUID as 36 ASCII characters.
constexpr size_t kUuidOffset = 8 + 4 + 4 + 4 + 1;
constexpr size_t kUuidLength = 36;
}  // namespace

void initialize() {
  static std::once_flag once;
  std::call_once(once, [] { openvdb::initialize(); });
}

void stampGrid(openvdb::GridBase& g, const LatticeMeta& m) {
  g.insertMeta("canopy_lattice_min", openvdb::Vec3IMetadata(openvdb::Vec3i(m.min.asVec3i())));
  g.insertMeta("canopy_lattice_max", openvdb::Vec3IMetadata(openvdb::Vec3i(m.max.asVec3i())));
  g.insertMeta("canopy_version", openvdb::StringMetadata(versionString()));
  g.insertMeta("canopy_source", openvdb::StringMetadata(m.source));
}

LatticeMeta readLatticeMeta(const openvdb::GridBase& g, const std::string& path) {
  auto mn = g.getMetadata<openvdb::Vec3IMetadata>("canopy_lattice_min");
  auto mx = g.getMetadata<openvdb::Vec3IMetadata>("canopy_lattice_max");
  if (!mn || !mx)
    throw invalidInput(path + ": grid '" + g.getName() +
                       "' lacks canopy_lattice_min/max metadata (not a Canopy lattice)");
  LatticeMeta m;
  m.min = openvdb::Coord(mn->value());
  m.max = openvdb::Coord(mx->value());
  if (m.max.x() < m.min.x() || m.max.y() < m.min.y() || m.max.z() < m.min.z())
    throw invalidInput(path + ": grid '" + g.getName() + "' has an empty lattice (max < min)");
  const openvdb::Coord d = m.dim();
  if (int64_t(d.x()) * d.y() * d.z() > kMaxLatticeCells)
    throw invalidInput(path + ": lattice " + std::to_string(d.x()) + "x" + std::to_string(d.y()) +
                       "x" + std::to_string(d.z()) + " has more than 2^33 cells (2048^3), the most Canopy reads");
  if (auto s = g.getMetadata<openvdb::StringMetadata>("canopy_source")) m.source = s->value();
  return m;
}

namespace {
// The UUID Canopy writes: RFC 4122 layout with version nibble 8 ("custom") and the variant bits
// set, built from the XXH64 of every other byte of the file. A reader recomputes it to detect
// truncation and corruption (OpenVDB's own reader accepts many truncated files silently).
std::string contentUuid(uint64_t contentHash) {
  const uint64_t b = hash64(&contentHash, sizeof contentHash, 0x63616e6f7079ULL);
  std::string hex = hex64(contentHash) + hex64(b);
  hex[12] = '8';
  hex[16] = "89ab"[(hex[16] - '0') & 3];
  return hex.substr(0, 8) + "-" + hex.substr(8, 4) + "-" + hex.substr(12, 4) + "-" +
         hex.substr(16, 4) + "-" + hex.substr(20, 12);
}
bool hasVdbMagic(const char* p) {
  int64_t magic;
  std::memcpy(&magic, p, 8);
  return magic == openvdb::OPENVDB_MAGIC;
}
}  // namespace

bool rewriteUuid(std::string& bytes) {
  if (bytes.size() < kUuidOffset + kUuidLength || !hasVdbMagic(bytes.data())) return false;
  Hasher h;
  h.update(bytes.data(), kUuidOffset);
  h.update(bytes.data() + kUuidOffset + kUuidLength, bytes.size() - kUuidOffset - kUuidLength);
  const std::string uuid = contentUuid(h.digest());
  std::memcpy(&bytes[kUuidOffset], uuid.data(), kUuidLength);
  return true;
}

// The XXH64 of every byte of a VDB file but its UUID: `head` (its first kUuidOffset + kUuidLength
// bytes), then the rest of `in`, read from just after the head.
static uint64_t contentHashAfter(const char* head, std::istream& in) {
  Hasher h;
  h.update(head, kUuidOffset);
  char buf[1 << 16];
  while (in) {
    in.read(buf, sizeof buf);
    h.update(buf, size_t(in.gcount()));
  }
  return h.digest();
}

// Checks the header and, for a file Canopy wrote (UUID version 8), that the UUID matches the
// content hash. Files re-saved by other tools (random version-4 UUIDs) skip the content check.
static void verifyHeaderAndContent(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  char head[kUuidOffset + kUuidLength];
  in.read(head, sizeof head);
  if (in.gcount() != std::streamsize(sizeof head) || !hasVdbMagic(head))
    throw invalidInput(path + ": not an OpenVDB file (bad magic or shorter than a VDB header)");
  uint32_t fileVersion;
  std::memcpy(&fileVersion, head + 8, 4);
  if (fileVersion > openvdb::OPENVDB_FILE_VERSION)
    throw invalidInput(path + ": OpenVDB file format version " + std::to_string(fileVersion) +
                       " is newer than this build reads (" + std::to_string(openvdb::OPENVDB_FILE_VERSION) + ")");
  const std::string stored(head + kUuidOffset, kUuidLength);
  if (stored[14] != '8') return;
  if (contentUuid(contentHashAfter(head, in)) != stored)
    throw invalidInput(path + ": content does not match its checksum (truncated or corrupted)");
}

void writeVdb(const std::string& path, const openvdb::GridPtrVec& grids,
              const openvdb::MetaMap& fileMeta) {
  initialize();
  AtomicOutput out(path);
  try {
    openvdb::io::File file(out.tempPath());
    file.write(grids, fileMeta);
    file.close();
  } catch (const std::exception& e) {
    throw ioError(path + ": cannot write VDB (" + e.what() + ")");
  }
  // The content UUID (as rewriteUuid), hashed from the file and written over OpenVDB's in place.
  std::fstream io(out.tempPath(), std::ios::binary | std::ios::in | std::ios::out);
  char head[kUuidOffset + kUuidLength];
  io.read(head, sizeof head);
  if (io.gcount() != std::streamsize(sizeof head) || !hasVdbMagic(head))
    throw runtimeError(path + ": OpenVDB wrote an unexpected header");
  const std::string uuid = contentUuid(contentHashAfter(head, io));
  io.clear();
  io.seekp(kUuidOffset);
  io.write(uuid.data(), kUuidLength);
  io.flush();
  if (!io) throw ioError(path + ": write failed (disk full?)");
  io.close();
  out.commit();
}

openvdb::GridBase::Ptr VdbFile::find(const std::string& name) const {
  if (!grids) return nullptr;
  for (auto& g : *grids)
    if (g && g->getName() == name) return g;
  return nullptr;
}

VdbFile readVdb(const std::string& path) {
  initialize();
  requireReadableFile(path);  // clear Io errors: missing, directory, unreadable
  verifyHeaderAndContent(path);
  VdbFile f;
  f.path = path;
  try {
    openvdb::io::File file(path);
    file.setCopyMaxBytes(0);  // read now, not lazily: corrupt data must fail here
    file.open(false);
    f.meta = file.getMetadata();
    f.grids = file.readAllGridMetadata();
    auto all = std::make_shared<openvdb::GridPtrVec>();
    for (auto& g : *f.grids) all->push_back(file.readGrid(g->getName()));
    f.grids = all;
    file.close();
    if (f.grids->empty()) throw std::runtime_error("it holds no grids");
  } catch (const std::exception& e) {
    std::string what = e.what();
    if (auto nl = what.find('\n'); nl != std::string::npos) what.resize(nl);
    throw invalidInput(path + ": not a readable OpenVDB file (" + what + ")");
  }
  return f;
}

bool gridHasDirectBeam(const openvdb::GridBase& grid) {
  const auto m = grid.getMetadata<openvdb::BoolMetadata>(kDirectBeamMeta);
  return !m || m->value();
}

bool sunBasesScattered(const std::string& path, const std::vector<bool>& beam) {
  if (!beam.empty() && !beam[0])
    throw invalidInput(path + ": the ambient base B00 is marked canopy_direct_beam = false (only sun bases can be)");
  size_t without = 0;
  for (size_t b = 1; b < beam.size(); ++b) without += beam[b] ? 0 : 1;
  if (without != 0 && without + 1 != beam.size())
    throw invalidInput(path + ": " + std::to_string(without) + " of the " + std::to_string(beam.size() - 1) +
                       " sun bases have no direct beam and the others do (mixed canopy_direct_beam); re-run canopy-lbsolve");
  return without != 0;
}

}  // namespace canopy::vdbio
