// canopy_file.cpp: the .canopy reader (see canopy_file.h). No OpenVDB here: this file is compiled
// into the sanitized tests and the fuzzer. It never trusts the file: every size, offset, count and
// pointer is checked before use, and every failure is a canopy::Error naming the file.
#include "formats/canopy_file.h"
#include "formats/page_coding.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <utility>

#include "canopy/atomic_file.h"
#include "canopy/errors.h"
#include "canopy/hash.h"

namespace canopy {
namespace {

std::string u64s(uint64_t v) { return std::to_string(v); }

[[noreturn]] void bad(const std::string& path, const std::string& what) {
  throw invalidInput(path + ": " + what);
}

template <class T>
std::vector<T> copyArray(const std::vector<unsigned char>& bytes, uint64_t offset, uint32_t count) {
  std::vector<T> out(count);
  if (count) std::memcpy(out.data(), bytes.data() + offset, size_t(count) * sizeof(T));
  return out;
}

// Each section kind's name in messages (the layout's) and in reports.
struct SectionNames {
  CanopySectionKind kind;
  const char* name;
  const char* label;
};
constexpr SectionNames kSectionNames[] = {
    {CanopySectionKind::Models, "Models", "models"},
    {CanopySectionKind::Instances, "Instances", "instances"},
    {CanopySectionKind::NodeTiles, "NodeTiles", "node_tiles"},
    {CanopySectionKind::PageTable, "PageTable", "page_table"},
    {CanopySectionKind::SceneLight, "SceneLight", "scene_light"},
    {CanopySectionKind::Metadata, "Metadata", "metadata"},
    {CanopySectionKind::HaarIndex, "HaarIndex", "haar_index"},
    {CanopySectionKind::SparseIndex, "SparseIndex", "sparse_index"},
    {CanopySectionKind::SceneSunLight, "SceneSunLight", "scene_sun_light"},
    {CanopySectionKind::PageExtents, "PageExtents", "page_extents"},
};

const char* sectionName(uint32_t kind) {
  for (const SectionNames& n : kSectionNames)
    if (uint32_t(n.kind) == kind) return n.name;
  return "unknown";
}

}  // namespace

const char* canopySectionLabel(uint32_t kind) {
  for (const SectionNames& n : kSectionNames)
    if (uint32_t(n.kind) == kind) return n.label;
  return "unknown";
}

bool canopyInvertAffine(const double m[12], double out[12]) {
  const double a = m[0], b = m[1], c = m[2], d = m[4], e = m[5], f = m[6], g = m[8], h = m[9], i = m[10];
  const double A = e * i - f * h, B = -(d * i - f * g), C = d * h - e * g;
  const double det = a * A + b * B + c * C;
  if (!(std::fabs(det) > 1e-300) || !std::isfinite(det)) return false;
  const double inv[9] = {A / det, -(b * i - c * h) / det, (b * f - c * e) / det,
                         B / det, (a * i - c * g) / det,  -(a * f - c * d) / det,
                         C / det, -(a * h - b * g) / det, (a * e - b * d) / det};
  for (int r = 0; r < 3; ++r) {
    for (int k = 0; k < 3; ++k) out[4 * r + k] = inv[3 * r + k];
    out[4 * r + 3] = -(inv[3 * r] * m[3] + inv[3 * r + 1] * m[7] + inv[3 * r + 2] * m[11]);
  }
  return true;
}

namespace {
// out = a * b for 3x4 affine matrices.
void composeAffine(const double a[12], const double b[12], double out[12]) {
  for (int r = 0; r < 3; ++r)
    for (int k = 0; k < 4; ++k)
      out[4 * r + k] = a[4 * r] * b[k] + a[4 * r + 1] * b[4 + k] + a[4 * r + 2] * b[8 + k] + (k == 3 ? a[4 * r + 3] : 0.0);
}
bool modelToUnitD(const CanopyModel& M, double out[12]) {
  double inv[12];
  if (!canopyInvertAffine(M.indexToModel, inv)) return false;
  // u = (p - origin + 0.5) / rootCells
  const double s = 1.0 / double(M.rootCells);
  double unit[12] = {s, 0, 0, (0.5 - M.octreeOrigin[0]) * s, 0, s, 0, (0.5 - M.octreeOrigin[1]) * s, 0, 0, s, (0.5 - M.octreeOrigin[2]) * s};
  composeAffine(unit, inv, out);
  return true;
}
}  // namespace

bool canopyModelToUnit(const CanopyModel& M, float out[12]) {
  double d[12];
  if (!modelToUnitD(M, d)) return false;
  for (int i = 0; i < 12; ++i) out[i] = float(d[i]);
  return true;
}

bool canopyWorldToUnit(const CanopyModel& M, const CanopyInstance& inst, float out[12]) {
  double mu[12], w[12], wi[12], d[12];
  if (!modelToUnitD(M, mu)) return false;
  for (int i = 0; i < 12; ++i) w[i] = inst.modelToWorld[i];
  if (!canopyInvertAffine(w, wi)) return false;
  composeAffine(mu, wi, d);
  for (int i = 0; i < 12; ++i) out[i] = float(d[i]);
  return true;
}

uint32_t canopyPageCrc(const void* page, uint32_t pageBytes) {
  const auto* p = static_cast<const unsigned char*>(page);
  constexpr size_t kCrcAt = offsetof(CanopyPageHeader, crc);
  static const unsigned char zeros[4] = {0, 0, 0, 0};
  uint32_t c = crc32(0, p, kCrcAt);
  c = crc32(c, zeros, 4);
  return crc32(c, p + kCrcAt + 4, pageBytes - kCrcAt - 4);
}

CanopyFile::CanopyFile(CanopyFile&& o) noexcept { *this = std::move(o); }

CanopyFile& CanopyFile::operator=(CanopyFile&& o) noexcept {
  if (this != &o) {
    if (fd_ >= 0) ::close(fd_);
    path_ = std::move(o.path_);
    fd_ = std::exchange(o.fd_, -1);
    memory_ = o.memory_;
    memorySize_ = o.memorySize_;
    resident_ = std::move(o.resident_);
    header_ = o.header_;
    sections_ = std::move(o.sections_);
    models_ = std::move(o.models_);
    instances_ = std::move(o.instances_);
    tiles_ = std::move(o.tiles_);
    pages_ = std::move(o.pages_);
    hasSceneLight_ = o.hasSceneLight_;
    sceneLight_ = o.sceneLight_;
    sceneLightBases_ = o.sceneLightBases_;
    sceneLightValues_ = std::move(o.sceneLightValues_);
    metadata_ = std::move(o.metadata_);
    haarIndex_ = std::move(o.haarIndex_);
    sparseIndex_ = std::move(o.sparseIndex_);
    extents_ = std::move(o.extents_);
  }
  return *this;
}

CanopyFile::~CanopyFile() {
  if (fd_ >= 0) ::close(fd_);
}

void CanopyFile::readAt(uint64_t offset, void* dst, size_t bytes) const {
  if (fd_ < 0) {
    if (offset > memorySize_ || bytes > memorySize_ - offset)
      bad(path_, "truncated: needs bytes up to " + u64s(offset + bytes) + ", file has " + u64s(memorySize_));
    if (bytes) std::memcpy(dst, memory_ + offset, bytes);
    return;
  }
  auto* out = static_cast<unsigned char*>(dst);
  size_t done = 0;
  while (done < bytes) {
    const ssize_t n = ::pread(fd_, out + done, bytes - done, off_t(offset + done));
    if (n < 0) {
      if (errno == EINTR) continue;
      throw ioError(path_ + ": read failed at offset " + u64s(offset + done) + ": " + std::strerror(errno));
    }
    if (n == 0)
      bad(path_, "truncated: needs bytes up to " + u64s(offset + bytes) + ", read ended at " + u64s(offset + done));
    done += size_t(n);
  }
}

CanopyFile CanopyFile::open(const std::string& path) {
  CanopyFile f;
  f.path_ = path;
  f.fd_ = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  if (f.fd_ < 0) throw ioError(path + ": cannot open: " + std::strerror(errno));
  struct stat st {};
  if (::fstat(f.fd_, &st) != 0) throw ioError(path + ": cannot stat: " + std::strerror(errno));
  if (!S_ISREG(st.st_mode)) throw ioError(path + ": not a regular file");
  noteInput(path);  // an output of the same run must not replace it (atomic_file.h)
  f.parseResident(uint64_t(st.st_size));
  return f;
}

CanopyFile CanopyFile::fromMemory(const void* data, size_t size, const std::string& name) {
  CanopyFile f;
  f.path_ = name;
  f.memory_ = static_cast<const unsigned char*>(data);
  f.memorySize_ = size;
  f.parseResident(size);
  return f;
}

const CanopySection* CanopyFile::findSection(CanopySectionKind kind) const {
  for (const auto& s : sections_)
    if (s.kind == uint32_t(kind)) return &s;
  return nullptr;
}

namespace {

// What the stages of CanopyFile::parseResident check and fill: the file's members, by reference,
// and what the earlier stages derive.
struct ResidentParse {
  const CanopyFile& file;  // findSection
  const std::string& P;
  const CanopyFileHeader& h;
  std::vector<unsigned char>& resident;
  std::vector<CanopySection>& sections;
  std::vector<CanopyModel>& models;
  std::vector<CanopyInstance>& instances;
  std::vector<CanopyNode>& tiles;
  std::vector<CanopyPageEntry>& pages;
  bool& hasSceneLight;
  CanopySceneLight& sceneLight;
  uint32_t& sceneLightBases;
  std::vector<float>& sceneLightValues;
  std::string& metadata;
  std::vector<uint32_t>& haarIndex;
  std::vector<uint32_t>& sparseIndex;
  std::vector<CanopyPageExtent>& extents;
  bool knownMinor = false;  // every section and page kind of the file is known (checkHeader)
  uint64_t tableEnd = 0;    // the end of the section table (checkHeader)
  uint64_t tileTotal = 0;   // NodeTiles' item count (copyTables)
};

// The header read into r.h: magic, version, checksum, sizes, page and item geometry, section count.
void checkHeader(ResidentParse& r, uint64_t fileBytes) {
  const std::string& P = r.P;
  const CanopyFileHeader& h = r.h;
  if (std::memcmp(h.magic, kCanopyMagic, 8) != 0) bad(P, "not a .canopy file (bad magic)");
  if (h.major > kCanopyMajor)
    throw unsupported(P + ": format version " + std::to_string(h.major) + "." + std::to_string(h.minor) +
                      " is newer than this reader (" + std::to_string(kCanopyMajor) + "." +
                      std::to_string(kCanopyMinor) + "); update canopy");
  if (h.major < 1) bad(P, "invalid format version " + std::to_string(h.major) + "." + std::to_string(h.minor));
  // Everything in a file of an older major, or of this major up to this minor, is known to this
  // reader; a newer minor may add section and page kinds that are skipped.
  r.knownMinor = h.major == 1 ? h.minor <= kCanopyMinor1 : h.minor <= kCanopyMinor;
  if (crc32(0, &h, offsetof(CanopyFileHeader, headerCrc)) != h.headerCrc) bad(P, "header checksum mismatch");
  if (h.headerBytes != sizeof(CanopyFileHeader)) bad(P, "header size " + u64s(h.headerBytes) + " != 128");
  if (h.fileBytes != fileBytes)
    bad(P, fileBytes < h.fileBytes ? "truncated: header says " + u64s(h.fileBytes) + " bytes, file has " + u64s(fileBytes)
                                   : "trailing bytes: header says " + u64s(h.fileBytes) + " bytes, file has " + u64s(fileBytes));
  if (h.pageBytes < 32768 || (h.pageBytes & (h.pageBytes - 1)) != 0 || h.pageBytes > (1u << 26))
    bad(P, "page size " + u64s(h.pageBytes) + " is not a power of two in [32 KiB, 64 MiB]");
  if (h.brickVoxels != kCanopyBrickVoxels || h.brickBytes != kCanopyBrickBytes)
    bad(P, "unsupported brick geometry (" + u64s(h.brickVoxels) + " voxels, " + u64s(h.brickBytes) + " bytes)");
  if (h.bricksPerPage != (h.pageBytes - sizeof(CanopyPageHeader)) / h.brickBytes)
    bad(P, "bricksPerPage " + u64s(h.bricksPerPage) + " inconsistent with the page size");
  // 4.0's shared-exponent items, or the float16 items before (converted as pages load: canopyPreparePage)
  if (h.lightItemBytes != (h.major >= 4 ? kCanopyLightItemBytes : kCanopyLightItemBytesHalf) ||
      h.lightItemsPerPage != (h.pageBytes - sizeof(CanopyPageHeader)) / h.lightItemBytes)
    bad(P, "unsupported light item geometry (" + u64s(h.lightItemBytes) + " bytes, " + u64s(h.lightItemsPerPage) + " per page)");
  if (h.pagesOffset != h.residentBytes || h.pagesOffset % h.pageBytes != 0 || h.pagesOffset > fileBytes)
    bad(P, "pages offset " + u64s(h.pagesOffset) + " invalid");
  // 5.0 is the version of compressed pages (a raw file keeps its older version: the writer's rule);
  // their sizes are checked against the file with the PageExtents section (readPageExtents)
  if (h.major < 5 ? h.pageCoding != kCanopyPageRaw : h.pageCoding != kCanopyPageZstd)
    bad(P, "page coding " + u64s(h.pageCoding) + " is not valid in a " + std::to_string(h.major) + "." + std::to_string(h.minor) + " file");
  if (h.pageCoding == kCanopyPageRaw &&
      ((fileBytes - h.pagesOffset) / h.pageBytes != h.pageCount || (fileBytes - h.pagesOffset) % h.pageBytes != 0))
    bad(P, "page count " + u64s(h.pageCount) + " does not match the file size");
  if (h.residentBytes > (uint64_t(1) << 34)) bad(P, "resident part of " + u64s(h.residentBytes) + " bytes is absurd");
  r.tableEnd = sizeof(CanopyFileHeader) + uint64_t(h.sectionCount) * sizeof(CanopySection);
  if (h.sectionCount == 0 || h.sectionCount > 64 || r.tableEnd > h.residentBytes)
    bad(P, "section count " + u64s(h.sectionCount) + " invalid");
}

// The section table: its checksum, then each section inside the resident part, sized, checksummed, once.
void checkSectionTable(ResidentParse& r) {
  const std::string& P = r.P;
  const CanopyFileHeader& h = r.h;
  if (crc32(0, r.resident.data() + sizeof(CanopyFileHeader), size_t(r.tableEnd - sizeof(CanopyFileHeader))) != h.sectionTableCrc)
    bad(P, "section table checksum mismatch");
  r.sections = copyArray<CanopySection>(r.resident, sizeof(CanopyFileHeader), h.sectionCount);
  for (size_t i = 0; i < r.sections.size(); ++i) {
    const CanopySection& s = r.sections[i];
    const std::string name = std::string("section ") + sectionName(s.kind);
    if (s.offset % kCanopySectionAlign != 0 || s.offset < r.tableEnd || s.offset > h.residentBytes ||
        s.bytes > h.residentBytes - s.offset)
      bad(P, name + " lies outside the resident part");
    if (s.itemBytes != 0 && uint64_t(s.itemBytes) * s.itemCount != s.bytes)
      bad(P, name + " size does not match its item count");
    if (crc32(0, r.resident.data() + s.offset, size_t(s.bytes)) != s.crc) bad(P, name + " checksum mismatch");
    for (size_t j = 0; j < i; ++j)
      if (r.sections[j].kind == s.kind) bad(P, "duplicate " + name);
  }
}

// Bytes of the resident part outside the header, the table and the sections must be zero (no CRC
// covers them, so anything else there is corruption).
void checkPadding(const ResidentParse& r) {
  const std::string& P = r.P;
  std::vector<std::pair<uint64_t, uint64_t>> used{{0, r.tableEnd}};
  for (const CanopySection& s : r.sections) used.emplace_back(s.offset, s.offset + s.bytes);
  std::sort(used.begin(), used.end());
  uint64_t at = 0;
  for (const auto& [b, e] : used) {
    if (b < at) bad(P, "sections overlap");
    for (uint64_t i = at; i < b; ++i)
      if (r.resident[size_t(i)] != 0) bad(P, "non-zero padding at offset " + u64s(i));
    at = e;
  }
  for (uint64_t i = at; i < r.resident.size(); ++i)
    if (r.resident[size_t(i)] != 0) bad(P, "non-zero padding at offset " + u64s(i));
}

// A section every file has, with its item size.
const CanopySection& requireSection(const ResidentParse& r, CanopySectionKind k, uint32_t itemBytes) {
  const CanopySection* s = r.file.findSection(k);
  if (!s) bad(r.P, std::string("missing section ") + sectionName(uint32_t(k)));
  if (s->itemBytes != itemBytes) bad(r.P, std::string("section ") + sectionName(uint32_t(k)) + " has the wrong item size");
  return *s;
}

// The four required sections, their counts against the header, copied into the tables.
void copyTables(ResidentParse& r) {
  const std::string& P = r.P;
  const CanopyFileHeader& h = r.h;
  const CanopySection& sm = requireSection(r, CanopySectionKind::Models, sizeof(CanopyModel));
  const CanopySection& si = requireSection(r, CanopySectionKind::Instances, sizeof(CanopyInstance));
  const CanopySection& st = requireSection(r, CanopySectionKind::NodeTiles, sizeof(CanopyNode) * 8);
  const CanopySection& sp = requireSection(r, CanopySectionKind::PageTable, sizeof(CanopyPageEntry));
  if (sm.itemCount != h.modelCount) bad(P, "model count differs between header and Models section");
  if (si.itemCount != h.instanceCount) bad(P, "instance count differs between header and Instances section");
  if (sp.itemCount != h.pageCount) bad(P, "page count differs between header and PageTable section");
  r.models = copyArray<CanopyModel>(r.resident, sm.offset, sm.itemCount);
  r.instances = copyArray<CanopyInstance>(r.resident, si.offset, si.itemCount);
  r.tiles = copyArray<CanopyNode>(r.resident, st.offset, st.itemCount * 8);
  r.pages = copyArray<CanopyPageEntry>(r.resident, sp.offset, sp.itemCount);
  r.tileTotal = st.itemCount;
}

// (5.0) The compressed pages' extents: present exactly with compressed pages, one per page, back to
// back from pagesOffset in page order to the end of the file, each no larger than a page can
// compress to and with a known filter.
void readPageExtents(ResidentParse& r, uint64_t fileBytes) {
  const std::string& P = r.P;
  const CanopyFileHeader& h = r.h;
  const CanopySection* se = r.file.findSection(CanopySectionKind::PageExtents);
  if (h.pageCoding == kCanopyPageRaw) {
    if (se) bad(P, "a file of raw pages has a PageExtents section");
    return;
  }
  if (!se) bad(P, "missing section PageExtents (compressed pages)");
  if (se->itemBytes != sizeof(CanopyPageExtent) || se->itemCount != h.pageCount)
    bad(P, "section PageExtents holds " + u64s(se->itemCount) + " entries, not one per page (" + u64s(h.pageCount) + ")");
  r.extents = copyArray<CanopyPageExtent>(r.resident, se->offset, se->itemCount);
  const uint64_t bound = canopyPageStoredBound(h.pageBytes);
  uint64_t at = h.pagesOffset;
  for (size_t i = 0; i < r.extents.size(); ++i) {
    const CanopyPageExtent& e = r.extents[i];
    if (e.offset != at || e.storedBytes == 0 || e.storedBytes > bound || e.storedBytes > fileBytes - at)
      bad(P, "page " + u64s(i) + " extent invalid (offset " + u64s(e.offset) + ", " + u64s(e.storedBytes) + " bytes)");
    if (!canopyPageFilterValid(e.filter)) bad(P, "page " + u64s(i) + " has an unknown filter " + u64s(e.filter));
    if (e.reserved != 0) bad(P, "page " + u64s(i) + " extent has non-zero reserved bytes");
    at += e.storedBytes;
  }
  if (at != fileBytes) bad(P, "the compressed pages end at " + u64s(at) + ", not at the end of the file (" + u64s(fileBytes) + ")");
}

// The scene light (SceneLight, 1.2's SceneSunLight): lattice, sizes, values non-negative and finite.
void readSceneLight(ResidentParse& r) {
  const std::string& P = r.P;
  const CanopyFileHeader& h = r.h;
  const CanopySection* sun = r.file.findSection(CanopySectionKind::SceneSunLight);
  if (const CanopySection* sl = r.file.findSection(CanopySectionKind::SceneLight)) {
    if (sl->bytes < sizeof(CanopySceneLight)) bad(P, "SceneLight section too small");
    std::memcpy(&r.sceneLight, r.resident.data() + sl->offset, sizeof r.sceneLight);
    for (double v : r.sceneLight.indexToWorld)
      if (!std::isfinite(v)) bad(P, "SceneLight has a non-finite transform");
    uint64_t n = 1;
    for (int a = 0; a < 3; ++a) {
      if (r.sceneLight.dim[a] <= 0 || r.sceneLight.dim[a] > 65536) bad(P, "SceneLight dimensions invalid");
      n *= uint64_t(r.sceneLight.dim[a]);
    }
    if (sl->bytes != sizeof(CanopySceneLight) + n * sizeof(float)) bad(P, "SceneLight size does not match its dimensions");
    // 1.2: the sun bases B01..B18 of the same lattice, one item each.
    if (sun) {
      if (h.major == 1 && h.minor < 2) bad(P, "a 1." + std::to_string(h.minor) + " file has a SceneSunLight section");
      if (sun->itemCount != kCanopySceneSunBases || uint64_t(sun->itemBytes) != n * sizeof(float))
        bad(P, "SceneSunLight holds " + u64s(sun->itemCount) + " bases of " + u64s(sun->itemBytes) + " bytes, not " +
                   u64s(kCanopySceneSunBases) + " of " + u64s(n * sizeof(float)) + " (SceneLight's lattice)");
    }
    r.sceneLightBases = sun ? 1 + kCanopySceneSunBases : 1;
    r.sceneLightValues.resize(size_t(n) * r.sceneLightBases);
    std::memcpy(r.sceneLightValues.data(), r.resident.data() + sl->offset + sizeof(CanopySceneLight), size_t(n) * sizeof(float));
    if (sun) std::memcpy(r.sceneLightValues.data() + n, r.resident.data() + sun->offset, size_t(n) * kCanopySceneSunBases * sizeof(float));
    for (size_t i = 0; i < r.sceneLightValues.size(); ++i)
      if (!(r.sceneLightValues[i] >= 0.0f) || r.sceneLightValues[i] > 3.0e38f)
        bad(P, "scene light base B" + std::string(i / n < 10 ? "0" : "") + std::to_string(i / n) + " value " + u64s(i % n) +
                   " is negative or not finite");
    r.hasSceneLight = true;
  } else if (sun) {
    bad(P, "SceneSunLight section without a SceneLight section");
  }
}

// The optional sections Metadata, HaarIndex (1.1) and SparseIndex (2.0), copied.
void readOptionalSections(ResidentParse& r) {
  const std::string& P = r.P;
  const CanopyFileHeader& h = r.h;
  if (const CanopySection* md = r.file.findSection(CanopySectionKind::Metadata))
    r.metadata.assign(reinterpret_cast<const char*>(r.resident.data() + md->offset), size_t(md->bytes));
  if (const CanopySection* hi = r.file.findSection(CanopySectionKind::HaarIndex)) {
    if (h.major == 1 && h.minor < 1) bad(P, "a 1.0 file has a HaarIndex section");
    if (hi->itemBytes != sizeof(uint32_t)) bad(P, "section HaarIndex has the wrong item size");
    r.haarIndex = copyArray<uint32_t>(r.resident, hi->offset, hi->itemCount);
  }
  if (const CanopySection* si = r.file.findSection(CanopySectionKind::SparseIndex)) {
    if (h.major < 2) bad(P, "a 1.x file has a SparseIndex section");
    if (si->itemBytes != sizeof(uint32_t)) bad(P, "section SparseIndex has the wrong item size");
    r.sparseIndex = copyArray<uint32_t>(r.resident, si->offset, si->itemCount);
  }
}

// Model m's record: name, transform, octree geometry, lattice, tile, brick, sparse and light ranges.
void checkModelRanges(const ResidentParse& r, uint32_t m) {
  const std::string& P = r.P;
  const CanopyFileHeader& h = r.h;
  const CanopyModel& M = r.models[m];
  const std::string name = "model " + std::to_string(m);
  if (M.name[sizeof M.name - 1] != 0) bad(P, name + " name is not NUL-terminated");
  for (double v : M.indexToModel)
    if (!std::isfinite(v)) bad(P, name + " has a non-finite transform");
  if (M.depth > kCanopyMaxDepth || M.brickSize != kCanopyBrickSize || M.brickBorder != kCanopyBrickBorder ||
      M.rootCells != (kCanopyBrickSize << M.depth))
    bad(P, name + " has an invalid octree geometry");
  for (int a = 0; a < 3; ++a) {
    if (M.latticeMax[a] < M.latticeMin[a] || int64_t(M.latticeMax[a]) - M.octreeOrigin[a] >= int64_t(M.rootCells) ||
        M.latticeMin[a] < M.octreeOrigin[a])
      bad(P, name + " lattice bounds do not fit its octree");
  }
  if (uint64_t(M.firstTile) + M.tileCount > r.tileTotal) bad(P, name + " tiles lie outside NodeTiles");
  const uint64_t bpp = h.bricksPerPage;
  // (2.0) the detail levels' bricks are sparse bricks: the brick pages hold the others
  if (M.sparseBricks > M.brickCount) bad(P, name + " has more sparse bricks than bricks");
  const uint64_t denseBricks = uint64_t(M.brickCount) - M.sparseBricks;
  if (M.detailLevels == 0 ? (M.sparseBricks | M.firstSparsePage | M.sparsePageCount | M.firstSparseIndex) != 0
                          : uint64_t(M.firstSparseIndex) + M.sparseBricks > r.sparseIndex.size() ||
                                uint64_t(M.firstSparsePage) + M.sparsePageCount > h.pageCount ||
                                (M.sparseBricks > 0) != (M.sparsePageCount > 0) ||
                                M.sparseBricks > uint64_t(M.sparsePageCount) * kCanopySparseMaxItemsPerPage)
    bad(P, name + " sparse bricks, pages or index out of range");
  if (M.brickPageCount != (denseBricks + bpp - 1) / bpp ||
      uint64_t(M.firstBrickPage) + M.brickPageCount > h.pageCount)
    bad(P, name + " brick pages out of range");
  const uint64_t lpp = h.lightItemsPerPage;
  const bool lit = (M.flags & kCanopyModelHasLight) != 0;
  if (M.detailLevels != 0 && h.major < 2) bad(P, name + " has detail levels in a 1." + std::to_string(h.minor) + " file");
  if (M.detailLevels > M.depth) bad(P, name + " has more detail levels (" + u64s(M.detailLevels) + ") than levels");
  for (int a = 0; a < 3; ++a)  // the light lattice's cells are whole blocks of the lattice
    if (M.detailLevels != 0 && (((M.latticeMin[a] | (M.latticeMax[a] + 1)) & ((1 << M.detailLevels) - 1)) != 0))
      bad(P, name + " lattice bounds are not whole light cells");
  // Light items: one per brick of levels 0..depth - detailLevels (every brick without detail).
  const uint64_t lightBricks = canopyLightLevelBricks(M);
  uint64_t levelSum = 0;
  for (uint32_t l = 0; l <= M.depth; ++l) levelSum += M.levelBricks[l];
  if (levelSum != M.brickCount) bad(P, name + " level brick counts do not add up to its bricks");
  if (M.detailLevels != 0 && uint64_t(M.brickCount) - M.sparseBricks != lightBricks)
    bad(P, name + " sparse bricks are not its detail levels' bricks");
  if ((lit ? M.lightCount != lightBricks : M.lightCount != 0) || M.lightPageCount != (uint64_t(M.lightCount) + lpp - 1) / lpp ||
      uint64_t(M.firstLightPage) + M.lightPageCount > h.pageCount)
    bad(P, name + " light items or pages out of range");
  if (M.flags & kCanopyModelScatteredSun) {
    if (h.major == 1 && h.minor < 1) bad(P, name + " has scattered-only sun bases in a 1.0 file");
    if (!lit) bad(P, name + " has scattered-only sun bases but no light");
  }
}

// Model m's Haar light (1.1): geometry, index and page ranges, group table; without it, zero fields.
void checkModelHaar(const ResidentParse& r, uint32_t m) {
  const std::string& P = r.P;
  const CanopyFileHeader& h = r.h;
  const CanopyModel& M = r.models[m];
  const std::string name = "model " + std::to_string(m);
  const bool lit = (M.flags & kCanopyModelHasLight) != 0;
  const bool haar = (M.flags & kCanopyModelHaarLight) != 0;
  if (haar) {
    if (h.major == 1 && h.minor < 1) bad(P, name + " has Haar light in a 1.0 file");
    if (!lit) bad(P, name + " has Haar light but no light items");
    if (M.haarPrecision > 1) bad(P, name + " Haar coefficient precision " + u64s(M.haarPrecision) + " is unknown");
    uint64_t groups = 1;
    for (int a = 0; a < 3; ++a) {
      const int64_t dim = (int64_t(M.latticeMax[a]) - M.latticeMin[a] + 1) >> M.detailLevels;  // the light lattice's
      if (M.haarBrickDims[a] != (dim + 2) / 3 || M.haarGroupDims[a] != (uint64_t(M.haarBrickDims[a]) + 3) / 4)
        bad(P, name + " Haar brick geometry does not match its lattice");
      groups *= M.haarGroupDims[a];
    }
    if (M.haarGroups > groups || uint64_t(M.haarIndexCount) != groups + uint64_t(kCanopyHaarGroupBricks) * M.haarGroups ||
        uint64_t(M.firstHaarIndex) + M.haarIndexCount > r.haarIndex.size())
      bad(P, name + " Haar index out of range");
    if (uint64_t(M.firstHaarPage) + M.haarPageCount > h.pageCount || (M.haarItemCount > 0) != (M.haarPageCount > 0) ||
        M.haarItemCount > uint64_t(M.haarPageCount) * kCanopyHaarMaxItemsPerPage)
      bad(P, name + " Haar pages out of range");
    // Every group table entry names a distinct block.
    std::vector<unsigned char> used(M.haarGroups, 0);
    const uint32_t* idx = r.haarIndex.data() + M.firstHaarIndex;
    for (uint64_t g = 0; g < groups; ++g) {
      if (idx[g] == kCanopyNone) continue;
      if (idx[g] >= M.haarGroups || used[idx[g]]) bad(P, name + " Haar group table entry " + u64s(g) + " is invalid");
      used[idx[g]] = 1;
    }
    for (uint32_t b = 0; b < M.haarGroups; ++b)
      if (!used[b]) bad(P, name + " Haar block " + u64s(b) + " is not in the group table");
  } else {
    // Without the flag every Haar field is zero (1.0's reserved bytes).
    static_assert(offsetof(CanopyModel, detailLevels) - offsetof(CanopyModel, haarPrecision) == 56, "the Haar fields of CanopyModel");
    const unsigned char* f = reinterpret_cast<const unsigned char*>(&M) + offsetof(CanopyModel, haarPrecision);
    for (size_t b = 0; b < offsetof(CanopyModel, detailLevels) - offsetof(CanopyModel, haarPrecision); ++b)
      if (f[b] != 0) bad(P, name + " has Haar fields but no Haar light flag");
  }
}

// Every tile of model m must be reached exactly once from the root, at a level < depth: no cycles,
// no shared or orphan tiles, every brick id in range.
void checkModelTree(const ResidentParse& r, uint32_t m) {
  const std::string& P = r.P;
  const CanopyModel& M = r.models[m];
  const std::string name = "model " + std::to_string(m);
  const bool lit = (M.flags & kCanopyModelHasLight) != 0;
  std::vector<unsigned char> seen(M.tileCount, 0);
  std::vector<std::pair<uint32_t, uint32_t>> stack;  // (tile, level of its nodes)
  auto checkNode = [&](const CanopyNode& n, uint32_t level) {
    if (n.brick != kCanopyNone && n.brick >= M.brickCount) bad(P, name + ": brick id " + u64s(n.brick) + " out of range");
    // a player takes the light of a brick at a light level from light item `brick`
    if (lit && n.brick != kCanopyNone && level <= canopyLightDepth(M) && n.brick >= M.lightCount)
      bad(P, name + ": brick " + u64s(n.brick) + " of light level " + u64s(level) + " has no light item");
    // a player finds a brick by its id (dense or sparse) and samples it by its level's form
    if (n.brick != kCanopyNone && M.detailLevels != 0 && (level > canopyLightDepth(M)) != (n.brick >= M.brickCount - M.sparseBricks))
      bad(P, name + ": brick " + u64s(n.brick) + " of level " + u64s(level) + " is not stored in its level's form");
    if (!(n.density >= 0.0f) || n.density > 3.0e38f) bad(P, name + ": node density is negative or not finite");
    if (n.child == kCanopyNone) return;
    if (n.child >= M.tileCount) bad(P, name + ": child tile " + u64s(n.child) + " out of range");
    if (level >= M.depth) bad(P, name + ": a node at the finest level has children");
    if (seen[n.child]) bad(P, name + ": tile " + u64s(n.child) + " is referenced twice");
    seen[n.child] = 1;
    stack.emplace_back(n.child, level + 1);
  };
  checkNode(M.root, 0);
  while (!stack.empty()) {
    const auto [t, level] = stack.back();
    stack.pop_back();
    const CanopyNode* nodes = r.tiles.data() + (size_t(M.firstTile) + t) * 8;
    for (int c = 0; c < 8; ++c) checkNode(nodes[c], level);
  }
  for (uint32_t t = 0; t < M.tileCount; ++t)
    if (!seen[t]) bad(P, name + ": tile " + u64s(t) + " is not reachable from the root");
}

// Every page belongs to exactly one model range (brick or light): no page is shared or orphaned.
void checkPageOwners(const ResidentParse& r) {
  const std::string& P = r.P;
  const CanopyFileHeader& h = r.h;
  std::vector<unsigned char> owner(h.pageCount, 0);
  for (const CanopyModel& M : r.models)
    for (auto [first, count] : {std::pair<uint32_t, uint32_t>{M.firstBrickPage, M.brickPageCount}, {M.firstLightPage, M.lightPageCount},
                                {M.firstHaarPage, M.haarPageCount}, {M.firstSparsePage, M.sparsePageCount}})
      for (uint32_t p = first; p < first + count; ++p) {
        if (owner[p]) bad(P, "page " + u64s(p) + " is claimed by two model ranges");
        owner[p] = 1;
      }
  if (r.knownMinor)  // a newer minor may add page kinds outside the model ranges
    for (uint32_t p = 0; p < h.pageCount; ++p)
      if (!owner[p]) bad(P, "page " + u64s(p) + " belongs to no model");
}

// Each instance names a model in range and has a finite transform.
void checkInstances(const ResidentParse& r) {
  const std::string& P = r.P;
  for (uint32_t i = 0; i < r.instances.size(); ++i) {
    if (r.instances[i].model >= r.models.size()) bad(P, "instance " + u64s(i) + " names model " + u64s(r.instances[i].model) + " out of range");
    for (float v : r.instances[i].modelToWorld)
      if (!std::isfinite(v)) bad(P, "instance " + u64s(i) + " has a non-finite transform");
  }
}

// Each page table entry: its index, model and payload, and the item range of its kind in its model.
void checkPageTable(const ResidentParse& r) {
  const std::string& P = r.P;
  const CanopyFileHeader& h = r.h;
  for (uint32_t i = 0; i < r.pages.size(); ++i) {
    const CanopyPageEntry& e = r.pages[i];
    const std::string name = "page " + std::to_string(i);
    if (std::memcmp(e.magic, kCanopyPageMagic, 4) != 0 || e.pageIndex != i) bad(P, name + ": page table entry is corrupt");
    if (e.model >= r.models.size()) bad(P, name + ": model out of range");
    if (e.payloadBytes > h.pageBytes - sizeof(CanopyPageHeader)) bad(P, name + ": payload larger than a page");
    const CanopyModel& M = r.models[e.model];
    if (e.kind == uint32_t(CanopyPageKind::Brick)) {
      if (i < M.firstBrickPage || i >= M.firstBrickPage + M.brickPageCount) bad(P, name + ": brick page outside its model's range");
      const uint32_t first = (i - M.firstBrickPage) * h.bricksPerPage;
      const uint32_t count = std::min<uint32_t>(h.bricksPerPage, M.brickCount - M.sparseBricks - first);
      if (e.firstItem != first || e.itemCount != count || e.payloadBytes != count * h.brickBytes)
        bad(P, name + ": brick range does not match its model");
    } else if (e.kind == uint32_t(CanopyPageKind::Light)) {
      if (i < M.firstLightPage || i >= M.firstLightPage + M.lightPageCount) bad(P, name + ": light page outside its model's range");
      const uint32_t first = (i - M.firstLightPage) * h.lightItemsPerPage;
      const uint32_t count = std::min<uint32_t>(h.lightItemsPerPage, M.lightCount - first);
      if (e.firstItem != first || e.itemCount != count || e.payloadBytes != count * h.lightItemBytes)
        bad(P, name + ": light item range does not match its model");
    } else if (e.kind == uint32_t(CanopyPageKind::HaarLight) && (M.flags & kCanopyModelHaarLight)) {
      if (i < M.firstHaarPage || i >= M.firstHaarPage + M.haarPageCount) bad(P, name + ": Haar page outside its model's range");
      // Haar pages hold whole items, numbered on from the model's previous Haar page.
      const uint32_t first = i == M.firstHaarPage ? 0 : r.pages[i - 1].firstItem + r.pages[i - 1].itemCount;
      if (e.firstItem != first || e.itemCount == 0 || e.itemCount > kCanopyHaarMaxItemsPerPage ||
          uint64_t(e.firstItem) + e.itemCount > M.haarItemCount || e.payloadBytes < 4 * (uint64_t(e.itemCount) + 1) ||
          (i + 1 == M.firstHaarPage + M.haarPageCount && e.firstItem + e.itemCount != M.haarItemCount))
        bad(P, name + ": Haar item range does not match its model");
    } else if (e.kind == uint32_t(CanopyPageKind::SparseBrick) && h.major >= 2) {
      if (i < M.firstSparsePage || i >= M.firstSparsePage + M.sparsePageCount) bad(P, name + ": sparse brick page outside its model's range");
      // whole sparse bricks in id order, numbered on from the model's previous sparse page
      const uint32_t dense = M.brickCount - M.sparseBricks;
      const uint32_t first = i == M.firstSparsePage ? dense : r.pages[i - 1].firstItem + r.pages[i - 1].itemCount;
      if (e.firstItem != first || e.itemCount == 0 || e.itemCount > kCanopySparseMaxItemsPerPage ||
          uint64_t(e.firstItem) + e.itemCount > M.brickCount || e.payloadBytes < 4 * (uint64_t(e.itemCount) + 1) ||
          (i + 1 == M.firstSparsePage + M.sparsePageCount && e.firstItem + e.itemCount != M.brickCount))
        bad(P, name + ": sparse brick range does not match its model");
    } else if (r.knownMinor) {
      bad(P, name + ": unknown page kind " + u64s(e.kind));
    }
  }
}

// Haar locations: every stored brick's (page, item) is in range and names a distinct item.
void checkHaarLocations(const ResidentParse& r) {
  const std::string& P = r.P;
  for (uint32_t m = 0; m < r.models.size(); ++m) {
    const CanopyModel& M = r.models[m];
    if (!(M.flags & kCanopyModelHaarLight)) continue;
    const std::string name = "model " + std::to_string(m);
    const uint64_t groups = uint64_t(M.haarGroupDims[0]) * M.haarGroupDims[1] * M.haarGroupDims[2];
    const uint32_t* loc = r.haarIndex.data() + M.firstHaarIndex + groups;
    std::vector<unsigned char> seen(M.haarItemCount, 0);
    uint64_t stored = 0;
    for (uint64_t i = 0; i < uint64_t(kCanopyHaarGroupBricks) * M.haarGroups; ++i) {
      if (loc[i] == kCanopyNone) continue;
      const uint32_t page = loc[i] >> kCanopyHaarItemBits, item = loc[i] & (kCanopyHaarMaxItemsPerPage - 1u);
      // (a page of the range may be of a kind a newer minor added: only a Haar page is sampled)
      if (page >= M.haarPageCount || r.pages[M.firstHaarPage + page].kind != uint32_t(CanopyPageKind::HaarLight) ||
          item >= r.pages[M.firstHaarPage + page].itemCount)
        bad(P, name + ": Haar brick location " + u64s(i) + " out of range");
      const uint32_t id = r.pages[M.firstHaarPage + page].firstItem + item;
      if (seen[id]) bad(P, name + ": Haar item " + u64s(id) + " is referenced twice");
      seen[id] = 1;
      ++stored;
    }
    if (stored != M.haarItemCount) bad(P, name + ": " + u64s(M.haarItemCount - stored) + " Haar items are not referenced");
  }
}

// Sparse brick locations: detail brick i is item (id - page.firstItem) of its page.
void checkSparseLocations(const ResidentParse& r) {
  for (uint32_t m = 0; m < r.models.size(); ++m) {
    const CanopyModel& M = r.models[m];
    const uint32_t dense = M.brickCount - M.sparseBricks;
    for (uint32_t i = 0; i < M.sparseBricks; ++i) {
      const uint32_t loc = r.sparseIndex[size_t(M.firstSparseIndex) + i];
      const uint32_t page = loc >> kCanopySparseItemBits, item = loc & (kCanopySparseMaxItemsPerPage - 1u);
      if (page >= M.sparsePageCount || r.pages[M.firstSparsePage + page].kind != uint32_t(CanopyPageKind::SparseBrick) ||
          r.pages[M.firstSparsePage + page].firstItem + item != dense + i || item >= r.pages[M.firstSparsePage + page].itemCount)
        bad(r.P, "model " + std::to_string(m) + ": sparse brick location " + u64s(i) + " is wrong");
    }
  }
}

}  // namespace

// Reads the header and the resident part, and checks them stage by stage (the stages above, in
// this order: each stage may rely on what the earlier ones checked).
void CanopyFile::parseResident(uint64_t fileBytes) {
  ResidentParse r{*this, path_, header_, resident_, sections_, models_, instances_, tiles_, pages_, hasSceneLight_,
                  sceneLight_, sceneLightBases_, sceneLightValues_, metadata_, haarIndex_, sparseIndex_, extents_};
  if (fileBytes < sizeof(CanopyFileHeader))
    bad(path_, "truncated: " + u64s(fileBytes) + " bytes, smaller than the 128-byte header");
  readAt(0, &header_, sizeof header_);
  checkHeader(r, fileBytes);
  resident_.resize(size_t(header_.residentBytes));
  readAt(0, resident_.data(), resident_.size());
  checkSectionTable(r);
  checkPadding(r);
  copyTables(r);
  readPageExtents(r, fileBytes);
  readSceneLight(r);
  readOptionalSections(r);
  for (uint32_t m = 0; m < models_.size(); ++m) {
    checkModelRanges(r, m);
    checkModelHaar(r, m);
    checkModelTree(r, m);
  }
  checkPageOwners(r);
  checkInstances(r);
  checkPageTable(r);
  checkHaarLocations(r);
  checkSparseLocations(r);
}

CanopyFile::BrickLocation CanopyFile::brickLocation(uint32_t m, uint32_t brick) const {
  const CanopyModel& M = models_.at(m);
  if (brick >= M.brickCount) throw invalidInput(path_ + ": brick " + u64s(brick) + " out of range");
  const uint32_t dense = M.brickCount - M.sparseBricks;
  if (brick < dense) return {canopyBrickPage(M, brick, header_.bricksPerPage), canopyBrickSlot(brick, header_.bricksPerPage), false};
  const uint32_t loc = sparseIndex_[size_t(M.firstSparseIndex) + brick - dense];
  return {M.firstSparsePage + (loc >> kCanopySparseItemBits), loc & (kCanopySparseMaxItemsPerPage - 1u), true};
}

CanopyHaarView CanopyFile::haarView(uint32_t m) const {
  const CanopyModel& M = models_.at(m);
  CanopyHaarView v{};
  v.index = haarIndex_.data() + M.firstHaarIndex;
  for (int a = 0; a < 3; ++a) {
    v.latticeMin[a] = M.latticeMin[a] >> M.detailLevels;  // the light lattice (detailLevels: 2.0)
    v.latticeMax[a] = M.latticeMax[a] >> M.detailLevels;
    v.groupDims[a] = M.haarGroupDims[a];
  }
  v.firstPage = M.firstHaarPage;
  v.fp16 = M.haarPrecision == uint32_t(haar::Precision::Fp16) ? 1u : 0u;
  return v;
}

// The offset table of a page of whole variable-size items (Haar and sparse brick pages): uint32
// offset[n + 1] at the payload's start, offset[0] = 4 (n + 1), increasing, multiples of 4, each item
// at least minItemBytes, offset[n] = payloadBytes; 1..maxItems items. Checked before any item is
// read, so that every item lies inside the payload. Returns "" or the problem (`item` names an
// item: "Haar item", "sparse brick").
static std::string checkItemOffsets(const unsigned char* page, uint32_t pageBytes, uint32_t maxItems, uint32_t minItemBytes,
                             const char* item, std::vector<uint32_t>& off) {
  CanopyPageHeader ph;
  std::memcpy(&ph, page, sizeof ph);
  const uint64_t n = ph.itemCount, pb = ph.payloadBytes;
  if (pb > pageBytes - sizeof(CanopyPageHeader) || n == 0 || n > maxItems || 4 * (n + 1) > pb)
    return std::string(item) + " page: item count or payload size invalid";
  off.resize(size_t(n) + 1);
  std::memcpy(off.data(), page + sizeof(CanopyPageHeader), off.size() * sizeof(uint32_t));
  if (off[0] != 4 * (n + 1) || off[size_t(n)] != pb) return std::string(item) + " page: item offsets do not span the payload";
  for (size_t i = 0; i < size_t(n); ++i)
    if (off[i + 1] <= off[i] || off[i + 1] % 4 != 0 || off[i + 1] - off[i] < minItemBytes)
      return std::string(item) + " " + std::to_string(i) + ": bad offset";
  return "";
}

std::string canopyCheckHaarPage(const void* pageImage, uint32_t pageBytes, bool fp16) {
  const auto* page = static_cast<const unsigned char*>(pageImage);
  const unsigned char* payload = page + sizeof(CanopyPageHeader);
  std::vector<uint32_t> off;
  const std::string bad = checkItemOffsets(page, pageBytes, kCanopyHaarMaxItemsPerPage, kCanopyHaarRecordBytes, "Haar item", off);
  if (!bad.empty()) return bad;
  const size_t n = off.size() - 1;
  const uint64_t entryBytes = fp16 ? 6 : 12;
  for (size_t i = 0; i < n; ++i) {
    auto what = [i](const char* problem) { return "Haar item " + std::to_string(i) + ": " + problem; };
    haar::BrickRecord rec[kCanopyLightBases];
    std::memcpy(rec, payload + off[i], sizeof rec);
    uint64_t entries = 0;
    for (uint32_t b = 0; b < kCanopyLightBases; ++b) {
      if (rec[b].first() != entries) return what("records are not a running sum of their masks");
      entries += uint64_t(haar::popcount64(rec[b].mask()));
    }
    const uint64_t need = (kCanopyHaarRecordBytes + entries * entryBytes + 3) / 4 * 4;
    if (need != uint64_t(off[i + 1]) - off[i]) return what("size does not match its coefficient count");
    const unsigned char* c = payload + off[i] + kCanopyHaarRecordBytes;
    for (uint64_t k = 0; k < 3 * entries; ++k) {
      float v;
      if (fp16) {
        uint16_t hv;
        std::memcpy(&hv, c + 2 * k, 2);
        v = halfToFloat(hv);
      } else {
        std::memcpy(&v, c + 4 * k, 4);
      }
      if (!std::isfinite(v)) return what("non-finite coefficient");
    }
  }
  return "";
}

std::string canopyCheckSparsePage(const void* pageImage, uint32_t pageBytes, bool uniformAllowed) {
  const auto* page = static_cast<const unsigned char*>(pageImage);
  const unsigned char* payload = page + sizeof(CanopyPageHeader);
  std::vector<uint32_t> off;
  const std::string bad = checkItemOffsets(page, pageBytes, kCanopySparseMaxItemsPerPage, kCanopySparseHeadBytes, "sparse brick", off);
  if (!bad.empty()) return bad;
  const size_t n = off.size() - 1;
  for (size_t i = 0; i < n; ++i) {
    auto what = [i](const char* problem) { return "sparse brick " + std::to_string(i) + ": " + problem; };
    uint32_t mask[kCanopySparseMaskWords];
    uint16_t prefix[kCanopySparseMaskWords];
    std::memcpy(mask, payload + off[i], sizeof mask);
    std::memcpy(prefix, payload + off[i] + sizeof mask, sizeof prefix);
    const uint32_t last = mask[kCanopySparseMaskWords - 1];
    const bool uniform = uniformAllowed && (last & kCanopySparseUniform) != 0;
    if ((last & ~kCanopySparseLastVoxels & ~(uniform ? kCanopySparseUniform : 0u)) != 0) return what("mask bits past the last voxel");
    mask[kCanopySparseMaskWords - 1] = last & kCanopySparseLastVoxels;
    uint32_t set = 0;
    for (uint32_t w = 0; w < kCanopySparseMaskWords; ++w) {
      if (prefix[w] != set) return what("prefix counts do not match its mask");
      set += haar::popcount32(mask[w]);
    }
    if (uniform && set == 0) return what("uniform density without a stored voxel");
    if (canopySparseItemBytes(set, uniform) != uint64_t(off[i + 1]) - off[i]) return what("size does not match its voxel count");
    uint32_t empty[kCanopySparseEmptyWords];
    std::memcpy(empty, payload + off[i] + sizeof mask + sizeof prefix, sizeof empty);
    for (uint32_t c = 0; c < kCanopyEmptyCells * kCanopyEmptyCells * kCanopyEmptyCells; ++c)
      if (((empty[c >> 5] >> (c & 31u)) & 1u) != uint32_t(canopySparseCellEmpty(mask, c % 8, (c / 8) % 8, c / 64)))
        return what("empty cells do not match its voxels");
    for (uint32_t v = 0; v < (uniform ? 1u : set); ++v) {
      float d;
      std::memcpy(&d, payload + off[i] + kCanopySparseHeadBytes + 4 * v, 4);
      if (!(d > 0.0f) || d > 3.0e38f) return what("stored density not positive and finite");
    }
  }
  return "";
}

CanopyLookup CanopyFile::descend(uint32_t m, float ux, float uy, float uz, uint32_t maxLevel) const {
  const CanopyModel& M = models_.at(m);
  return canopyDescend(tiles(m), M.tileCount, M.root, M.depth, ux, uy, uz, maxLevel);
}

void CanopyFile::readPage(uint32_t index, void* dst) const {
  if (index >= pages_.size()) throw invalidInput(path_ + ": page " + u64s(index) + " out of range");
  const CanopyPageEntry& e = pages_[index];
  if (header_.pageCoding == kCanopyPageZstd) {
    const CanopyPageExtent& x = extents_[index];
    thread_local std::vector<unsigned char> stored;
    stored.resize(x.storedBytes);
    readAt(x.offset, stored.data(), stored.size());
    if (crc32(0, stored.data(), stored.size()) != x.storedCrc) bad(path_, "page " + std::to_string(index) + ": stored bytes checksum mismatch");
    const std::string problem =
        canopyPageDecode(stored.data(), stored.size(), x.filter, static_cast<unsigned char*>(dst), header_.pageBytes);
    if (!problem.empty()) bad(path_, "page " + std::to_string(index) + ": " + problem);
  } else {
    readAt(header_.pagesOffset + uint64_t(index) * header_.pageBytes, dst, header_.pageBytes);
  }
  CanopyPageHeader ph;
  std::memcpy(&ph, dst, sizeof ph);
  const std::string name = "page " + std::to_string(index);
  if (std::memcmp(&ph, &e, sizeof ph) != 0) bad(path_, name + ": page header differs from the page table");
  if (canopyPageCrc(dst, header_.pageBytes) != ph.crc) bad(path_, name + ": checksum mismatch");
  // A Haar or sparse brick page's offsets and masks index into it on the device: its structure is
  // checked too.
  if (ph.kind == uint32_t(CanopyPageKind::HaarLight)) {
    const std::string problem = canopyCheckHaarPage(dst, header_.pageBytes, models_[ph.model].haarPrecision != 0);
    if (!problem.empty()) bad(path_, name + ": " + problem);
  } else if (ph.kind == uint32_t(CanopyPageKind::SparseBrick) && header_.major >= 2) {
    const std::string problem = canopyCheckSparsePage(dst, header_.pageBytes, header_.major >= 3);
    if (!problem.empty()) bad(path_, name + ": " + problem);
  }
}

std::vector<unsigned char> CanopyFile::readPage(uint32_t index) const {
  std::vector<unsigned char> page(header_.pageBytes);
  readPage(index, page.data());
  return page;
}

std::vector<std::string> verifyCanopyPages(const CanopyFile& f) {
  std::vector<std::string> problems;
  std::vector<unsigned char> page(f.header().pageBytes);
  for (uint32_t i = 0; i < f.pageCount(); ++i) {
    try {
      f.readPage(i, page.data());
    } catch (const Error& e) {
      problems.push_back(e.what());
    }
  }
  return problems;
}

}  // namespace canopy
