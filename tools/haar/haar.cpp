// haar.cpp: canopy-haar's core (see haar.h). The only OpenVDB translation unit of the tool.
#include "haar.h"

#include <chrono>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <sstream>

#include <openvdb/tools/Dense.h>

#include "canopy/atomic_file.h"
#include "canopy/cli.h"
#include "canopy/hash.h"
#include "formats/lattice_vdb.h"
#include "plot.h"

namespace canopy::haar {

Precision parsePrecision(const std::string& s) {
  if (s == "fp32") return Precision::Fp32;
  if (s == "fp16") return Precision::Fp16;
  if (s == "quant") return Precision::Quant;
  throw usageError("--precision must be fp32, fp16 or quant, not '" + s + "'");
}
const char* precisionName(Precision p) {
  return p == Precision::Quant ? "quant" : (p == Precision::Fp16 ? "fp16" : "fp32");
}

// ---- reading the light field -----------------------------------------------------------------
struct LightField {
  std::string path;
  vdbio::VdbFile file;
  LatticeGeom geom;
  double indexToModel[16];
  std::vector<openvdb::Vec3SGrid::Ptr> grids;
};
void LightFieldDeleter::operator()(LightField* p) const { delete p; }
const LatticeGeom& lightGeom(const LightField& f) { return f.geom; }
uint32_t lightBaseCount(const LightField& f) { return uint32_t(f.grids.size()); }

LightFieldPtr openLightField(const std::string& path) {
  LightFieldPtr f(new LightField);
  f->path = path;
  f->file = vdbio::readVdb(path);
  for (uint32_t b = 0; b < uint32_t(kMaxBases); ++b) {
    if (!f->file.find(baseName(b))) break;
    f->grids.push_back(f->file.require<openvdb::Vec3SGrid>(baseName(b)));
  }
  if (f->grids.empty())
    throw invalidInput(path + ": no grid named B00 (expected an lbsolve output with Vec3 grids B00..B18)");
  if (f->grids.size() != 19)
    logWarn(path + ": " + std::to_string(f->grids.size()) + " base grids (an lbsolve output has 19)");
  const vdbio::LatticeMeta lm = vdbio::readLatticeMeta(*f->grids[0], path);
  const int32_t mn[3] = {lm.min.x(), lm.min.y(), lm.min.z()};
  const int32_t mx[3] = {lm.max.x(), lm.max.y(), lm.max.z()};
  f->geom = LatticeGeom::fromBounds(mn, mx, path);
  const openvdb::math::Transform& xf = f->grids[0]->transform();
  if (!xf.isLinear()) throw invalidInput(path + ": grid B00 has a non-linear transform");
  const openvdb::Mat4d m = xf.baseMap()->getAffineMap()->getMat4();
  for (int r = 0; r < 4; ++r)
    for (int c = 0; c < 4; ++c) f->indexToModel[4 * r + c] = m(r, c);
  const openvdb::CoordBBox lattice(lm.min, lm.max);
  for (auto& g : f->grids) {
    const vdbio::LatticeMeta gm = vdbio::readLatticeMeta(*g, path);
    if (gm.min != lm.min || gm.max != lm.max)
      throw invalidInput(path + ": grid " + g->getName() + " has another lattice than B00");
    if (g->transform() != xf) throw invalidInput(path + ": grid " + g->getName() + " has another transform than B00");
    if (!g->getMetadata<openvdb::Vec3IMetadata>("canopy_direction"))
      throw invalidInput(path + ": grid " + g->getName() + " lacks canopy_direction metadata");
    const openvdb::CoordBBox active = g->evalActiveVoxelBoundingBox();
    if (!active.empty() && !lattice.isInside(active))
      throw invalidInput(path + ": grid " + g->getName() + " has active voxels outside the lattice");
  }
  // The direct-beam mark (lbsolve): never on the ambient base, and the same on every sun base.
  std::vector<bool> beam;
  for (const auto& g : f->grids) beam.push_back(vdbio::gridHasDirectBeam(*g));
  vdbio::sunBasesScattered(path, beam);
  return f;
}

bool lightBaseHasBeam(const LightField& f, uint32_t b) { return vdbio::gridHasDirectBeam(*f.grids.at(b)); }

DenseLight lightBase(const LightField& f, uint32_t b, std::array<int32_t, 3>& dir) {
  const auto& g = f.grids.at(b);
  const openvdb::Vec3i d = g->metaValue<openvdb::Vec3i>("canopy_direction");
  for (int a = 0; a < 3; ++a) dir[size_t(a)] = d[a];
  if (std::abs(d[0]) > 1 || std::abs(d[1]) > 1 || std::abs(d[2]) > 1)
    throw invalidInput(f.path + ": grid " + g->getName() + " has canopy_direction outside -1..1");
  DenseLight out;
  out.rgb.assign(3 * f.geom.cells, 0.0f);
  out.activeVoxels = g->activeVoxelCount();
  const openvdb::CoordBBox box(openvdb::Coord(f.geom.min[0], f.geom.min[1], f.geom.min[2]),
                               openvdb::Coord(f.geom.max[0], f.geom.max[1], f.geom.max[2]));
  openvdb::tools::Dense<openvdb::Vec3s, openvdb::tools::LayoutXYZ> dense(
      box, reinterpret_cast<openvdb::Vec3s*>(out.rgb.data()));
  openvdb::tools::copyToDense(*g, dense);
  return out;
}

// ---- reports ------------------------------------------------------------------------------
namespace {

nlohmann::json numberOrNull(double v) { return std::isfinite(v) ? nlohmann::json(v) : nlohmann::json(); }

nlohmann::json baseJson(const BaseReport& r) {
  return {{"base", baseName(r.base)},
          {"direction", {r.direction[0], r.direction[1], r.direction[2]}},
          {"threshold", r.threshold},
          {"bytes_dense_fp32", r.denseBytes},
          {"bytes_sparse", r.sparseBytes},
          {"bytes_compressed", r.compressedBytes},
          {"ratio_dense", r.compressedBytes ? double(r.denseBytes) / double(r.compressedBytes) : 0.0},
          {"ratio_sparse", r.compressedBytes ? double(r.sparseBytes) / double(r.compressedBytes) : 0.0},
          {"max_error", r.maxError},
          {"rms_error", r.rmsError},
          {"psnr_db", numberOrNull(r.psnr)},
          {"value_max", r.valueMax},
          {"bricks", r.bricks},
          {"raw_bricks", r.rawBricks},
          {"coefficients", r.coefficients},
          {"search_probes", r.probes}};
}

nlohmann::json overallJson(const OverallReport& o) {
  return {{"bytes_dense_fp32", o.denseBytes},
          {"bytes_sparse", o.sparseBytes},
          {"bytes_file", o.fileBytes},
          {"ratio_dense", o.fileBytes ? double(o.denseBytes) / double(o.fileBytes) : 0.0},
          {"ratio_sparse", o.fileBytes ? double(o.sparseBytes) / double(o.fileBytes) : 0.0},
          {"max_error", o.maxError},
          {"rms_error", o.rmsError},
          {"psnr_db", numberOrNull(o.psnr)},
          {"value_max", o.valueMax},
          {"stored_bricks", o.slots}};
}

std::string fmtBytes(uint64_t b) {
  char buf[32];
  if (b >= (uint64_t(1) << 20))
    std::snprintf(buf, sizeof buf, "%.2f MiB", double(b) / (1 << 20));
  else
    std::snprintf(buf, sizeof buf, "%.1f KiB", double(b) / 1024);
  return buf;
}

void logTable(const std::vector<BaseReport>& rs, const OverallReport& o) {
  logInfo("base  threshold    dense fp32 -> compressed   ratio     RMS err     max err   PSNR dB");
  char line[256];
  for (const auto& r : rs) {
    std::snprintf(line, sizeof line, "%-4s %10.4g %13s -> %-12s %6.2fx %11.4g %11.4g %8.2f",
                  baseName(r.base).c_str(), r.threshold, fmtBytes(r.denseBytes).c_str(),
                  fmtBytes(r.compressedBytes).c_str(),
                  r.compressedBytes ? double(r.denseBytes) / r.compressedBytes : 0.0, r.rmsError,
                  r.maxError, r.psnr);
    logInfo(line);
  }
  std::snprintf(line, sizeof line,
                "all: dense %s, sparse %s -> file %s: %.2fx vs dense, %.2fx vs sparse; RMS %.4g, max %.4g, "
                "PSNR %.2f dB",
                fmtBytes(o.denseBytes).c_str(), fmtBytes(o.sparseBytes).c_str(), fmtBytes(o.fileBytes).c_str(),
                o.fileBytes ? double(o.denseBytes) / o.fileBytes : 0.0,
                o.fileBytes ? double(o.sparseBytes) / o.fileBytes : 0.0, o.rmsError, o.maxError, o.psnr);
  logInfo(line);
}

void writeTemp(const AtomicOutput& out, const std::string& bytes) {
  std::ofstream f(out.tempPath(), std::ios::binary | std::ios::trunc);
  f.write(bytes.data(), std::streamsize(bytes.size()));
  f.flush();
  if (!f) throw ioError(out.target() + ": write failed (disk full?)");
}

std::string metaJson(const std::string& input, const nlohmann::json& options) {
  nlohmann::json m = {{"tool", "canopy-haar"}, {"version", versionString()},
                      {"source", vdbio::describeSource(input)}, {"options", options}};
  return m.dump();
}

}  // namespace

// ---- compress -----------------------------------------------------------------------------
nlohmann::json compressLight(const CompressOptions& o) {
  const auto t0 = std::chrono::steady_clock::now();
  if (!(o.threshold >= 0) || !std::isfinite(o.threshold))
    throw usageError("--threshold must be a finite number >= 0");
  if (o.maxError >= 0 && !std::isfinite(o.maxError)) throw usageError("--max-error must be finite");
  if (o.precision == Precision::Quant && o.maxError < 0 && !(o.threshold > 0))
    throw usageError("--precision quant needs --threshold T > 0 (the quantisation step) or --max-error E");
  AtomicOutput out(o.output);  // fail early on an unwritable destination
  LightFieldPtr f = openLightField(o.input);
  const LatticeGeom& g = f->geom;
  logInfo("canopy-haar: " + o.input + ": lattice " + std::to_string(g.dims[0]) + "x" + std::to_string(g.dims[1]) + "x" +
          std::to_string(g.dims[2]) + ", " + std::to_string(f->grids.size()) + " bases, " +
          std::to_string(g.bricks) + " bricks");

  ChaarAssembly a;
  a.geom = g;
  a.precision = o.precision;
  std::memcpy(a.indexToModel, f->indexToModel, sizeof a.indexToModel);
  const bool search = o.maxError >= 0;
  a.threshold = search ? -1.0f : o.threshold;
  a.maxErrorTarget = search ? o.maxError : -1.0f;
  nlohmann::json opts = {{"precision", precisionName(o.precision)}};
  if (search)
    opts["max_error"] = o.maxError;
  else
    opts["threshold"] = o.threshold;
  a.meta = metaJson(o.input, opts);
  std::vector<uint64_t> active;
  std::vector<int> probes;
  Progress progress("encoding bases", int64_t(f->grids.size()));
  for (uint32_t b = 0; b < f->grids.size(); ++b) {
    std::array<int32_t, 3> dir;
    const DenseLight light = lightBase(*f, b, dir);
    const LiftedBase lifted(g, light, o.precision, o.input + " grid " + baseName(b));
    int n = 0;
    const float t = search ? lifted.searchThreshold(o.maxError, &n) : o.threshold;
    a.codes.push_back(lifted.encode(t));
    a.directions.push_back(dir);
    a.flags.push_back(lightBaseHasBeam(*f, b) ? 0u : uint32_t(kChaarBaseScattered));
    a.valueMax.push_back(lifted.valueMax());
    active.push_back(light.activeVoxels);
    probes.push_back(n);
    if (search && a.codes.back().maxError > o.maxError)  // cannot happen: the search measured it
      throw runtimeError("internal: base " + baseName(b) + " exceeds --max-error after the search");
    progress.add();
  }
  progress.done();
  ChaarData d = assembleChaar(a);
  const std::vector<uint8_t> bytes = serializeChaar(d);
  writeTemp(out, std::string(bytes.begin(), bytes.end()));
  out.commit();
  OverallReport overall;
  std::vector<BaseReport> rs = baseReports(d, a, active, bytes.size(), overall);
  for (size_t i = 0; i < rs.size(); ++i) rs[i].probes = probes[i];
  logTable(rs, overall);
  nlohmann::json rep = {{"input", o.input}, {"output", o.output}, {"precision", precisionName(o.precision)},
                        {"bases", nlohmann::json::array()}, {"overall", overallJson(overall)},
                        {"seconds", secondsSince(t0)}};
  if (search)
    rep["max_error_target"] = o.maxError;
  else
    rep["threshold"] = o.threshold;
  for (const auto& r : rs) rep["bases"].push_back(baseJson(r));
  return rep;
}

// ---- decode -------------------------------------------------------------------------------
nlohmann::json decodeToVdb(const std::string& input, const std::string& output) {
  const auto t0 = std::chrono::steady_clock::now();
  AtomicOutput probe(output);  // unwritable destination fails before decoding
  const ChaarData d = readChaar(input);
  vdbio::initialize();
  const ChaarHeader& h = d.header;
  openvdb::Mat4d m;
  for (int r = 0; r < 4; ++r)
    for (int c = 0; c < 4; ++c) m(r, c) = h.indexToModel[4 * r + c];
  const auto xf = openvdb::math::Transform::createLinearTransform(m);
  vdbio::LatticeMeta lm;
  lm.min = openvdb::Coord(h.latticeMin[0], h.latticeMin[1], h.latticeMin[2]);
  lm.max = openvdb::Coord(h.latticeMax[0], h.latticeMax[1], h.latticeMax[2]);
  lm.source = vdbio::describeSource(input);
  const openvdb::CoordBBox box(lm.min, lm.max);
  openvdb::GridPtrVec grids;
  std::vector<float> dense;
  uint64_t activeTotal = 0;
  for (uint32_t b = 0; b < d.baseCount(); ++b) {
    decodeBaseDense(d, b, dense);
    auto g = openvdb::Vec3SGrid::create(openvdb::Vec3s(0.0f));
    g->setName(baseName(b));
    g->setTransform(xf->copy());
    g->setGridClass(openvdb::GRID_UNKNOWN);
    openvdb::tools::Dense<openvdb::Vec3s, openvdb::tools::LayoutXYZ> dv(
        box, reinterpret_cast<openvdb::Vec3s*>(dense.data()));
    openvdb::tools::copyFromDense(dv, *g, openvdb::Vec3s(0.0f), /*serial=*/true);
    g->pruneGrid(0.0f);
    vdbio::stampGrid(*g, lm);
    const ChaarBaseEntry& e = d.bases[b];
    g->insertMeta("canopy_direction", openvdb::Vec3IMetadata(openvdb::Vec3i(e.direction[0], e.direction[1], e.direction[2])));
    g->insertMeta(vdbio::kDirectBeamMeta, openvdb::BoolMetadata((e.flags & kChaarBaseScattered) == 0));
    g->insertMeta("canopy_haar_threshold", openvdb::FloatMetadata(e.threshold));
    g->insertMeta("canopy_haar_max_error", openvdb::FloatMetadata(e.maxError));
    activeTotal += g->activeVoxelCount();
    grids.push_back(g);
  }
  vdbio::writeVdb(output, grids);
  logInfo("canopy-haar: " + output + ": " + std::to_string(grids.size()) + " decoded bases, " + std::to_string(activeTotal) +
          " active voxels");
  return {{"input", input}, {"output", output}, {"bases", d.baseCount()}, {"active_voxels", activeTotal},
          {"seconds", secondsSince(t0)}};
}

// ---- info / verify -------------------------------------------------------------------------
nlohmann::json chaarInfo(const std::string& input) {
  const ChaarData d = readChaar(input);
  const ChaarHeader& h = d.header;
  nlohmann::json meta = nlohmann::json::parse(d.meta, nullptr, /*allow_exceptions=*/false);
  nlohmann::json rep = {
      {"file", input},
      {"format_version", std::to_string(h.versionMajor) + "." + std::to_string(h.versionMinor)},
      {"bytes", h.fileSize},
      {"precision", precisionName(d.precision())},
      {"lattice_min", {h.latticeMin[0], h.latticeMin[1], h.latticeMin[2]}},
      {"lattice_max", {h.latticeMax[0], h.latticeMax[1], h.latticeMax[2]}},
      {"brick_grid", {h.brickDims[0], h.brickDims[1], h.brickDims[2]}},
      {"stored_bricks", h.slotCount},
      {"coefficients", h.coefCount},
      {"threshold", numberOrNull(h.threshold >= 0 ? double(h.threshold) : NAN)},
      {"max_error_target", numberOrNull(h.maxErrorTarget >= 0 ? double(h.maxErrorTarget) : NAN)},
      {"index_to_model", std::vector<double>(h.indexToModel, h.indexToModel + 16)},
      {"meta", meta.is_discarded() ? nlohmann::json(d.meta) : meta},
      {"bases", nlohmann::json::array()}};
  for (uint32_t b = 0; b < d.baseCount(); ++b) {
    const ChaarBaseEntry& e = d.bases[b];
    rep["bases"].push_back({{"base", baseName(b)},
                            {"direction", {e.direction[0], e.direction[1], e.direction[2]}},
                            {"threshold", e.threshold},
                            {"bytes", d.baseBytes(b)},
                            {"coefficients", e.coefCount},
                            {"bricks", e.brickCount},
                            {"raw_bricks", e.rawBrickCount},
                            {"max_error", e.maxError},
                            {"rms_error", e.rmsError},
                            {"value_max", e.valueMax},
                            {"direct_beam", (e.flags & kChaarBaseScattered) == 0}});
  }
  return rep;
}

std::string formatChaarInfo(const nlohmann::json& info) {
  const auto& lo = info["lattice_min"];
  const auto& hi = info["lattice_max"];
  const auto& bg = info["brick_grid"];
  const uint64_t bricks = bg[0].get<uint64_t>() * bg[1].get<uint64_t>() * bg[2].get<uint64_t>();
  std::string text = info["file"].get<std::string>() + ": .chaar " + info["format_version"].get<std::string>() + ", " +
                     info["precision"].get<std::string>() + ", " + std::to_string(info["bases"].size()) + " bases, lattice ";
  for (int a = 0; a < 3; ++a) text += std::to_string(hi[a].get<int64_t>() - lo[a].get<int64_t>() + 1) + (a < 2 ? "x" : "");
  text += ", " + std::to_string(info["stored_bricks"].get<uint64_t>()) + " stored bricks of " + std::to_string(bricks) + ", " +
          fmtBytes(info["bytes"].get<uint64_t>()) + "\n";
  for (const auto& e : info["bases"]) {
    const auto& dir = e["direction"];
    char line[220];
    std::snprintf(line, sizeof line, "  %s dir (%2d,%2d,%2d) threshold %-10.4g %9llu coefs %7u bricks  max err %.4g  RMS %.4g%s\n",
                  e["base"].get<std::string>().c_str(), dir[0].get<int>(), dir[1].get<int>(), dir[2].get<int>(),
                  e["threshold"].get<double>(), (unsigned long long)e["coefficients"].get<uint64_t>(),
                  e["bricks"].get<unsigned>(), e["max_error"].get<double>(), e["rms_error"].get<double>(),
                  e["direct_beam"].get<bool>() ? "" : "  scattered only");
    text += line;
  }
  return text;
}

nlohmann::json verifyChaar(const std::string& input) {
  // parseChaar checks magic, version, sizes, checksums, slot bijection, record order and ranges,
  // finite coefficients. Decoding every brick then proves every value is finite.
  const ChaarData d = readChaar(input);
  std::vector<float> dense;
  for (uint32_t b = 0; b < d.baseCount(); ++b) {
    decodeBaseDense(d, b, dense);
    for (float v : dense)
      if (!std::isfinite(v)) throw invalidInput(input + ": base " + baseName(b) + " decodes to a non-finite value");
  }
  return {{"file", input}, {"ok", true}, {"bases", d.baseCount()}, {"bytes", d.header.fileSize}};
}

std::string formatVerify(const nlohmann::json& report) {
  return report["file"].get<std::string>() + ": OK (checksums, indices and " + std::to_string(report["bases"].get<uint32_t>()) +
         " decoded bases)\n";
}

// ---- sweep --------------------------------------------------------------------------------
namespace {

// One base at one threshold: its coefficient bytes and errors.
struct SweepCell {
  uint64_t coefBytes;
  double maxErr, sumSq, rms, peak;
};

// What encoding every base at every threshold measured: stats[t][b], the stored bricks of the file.
struct SweepStats {
  std::vector<std::vector<SweepCell>> stats;
  std::vector<uint64_t> active;
  std::vector<double> peaks;
  uint32_t slots = 0;
};

// The plot of the sweep: one series per base and one for the whole file.
struct SweepPlot {
  PlotSpec plot;
  PlotSeries overall;
  std::vector<PlotSeries> bases;
};

// The sums over the bases at one threshold.
struct SweepTotals {
  uint64_t totalCoefBytes = 0, sparse = 0;
  double maxErr = 0, sumSq = 0, peak = 0;
};

// Refuses an empty --thresholds list or a threshold the precision cannot take.
void checkSweepOptions(const SweepOptions& o) {
  if (o.thresholds.empty()) throw usageError("--thresholds needs at least one value");
  for (float t : o.thresholds)
    if (!(t >= 0) || !std::isfinite(t)) throw usageError("--thresholds must be finite numbers >= 0");
  if (o.precision == Precision::Quant)
    for (float t : o.thresholds)
      if (!(t > 0)) throw usageError("--precision quant: every threshold (the quantisation step) must be > 0");
}

// Encodes every base at every threshold and keeps the sizes and errors.
SweepStats measureSweep(const SweepOptions& o, const LightField& f) {
  const LatticeGeom& g = f.geom;
  const size_t nt = o.thresholds.size(), nb = f.grids.size();
  SweepStats s;
  s.stats.assign(nt, std::vector<SweepCell>(nb));
  std::vector<uint8_t> anyLight(g.bricks, 0);
  s.active.resize(nb);
  s.peaks.resize(nb);
  Progress progress("sweeping bases", int64_t(nb));
  for (uint32_t b = 0; b < nb; ++b) {
    std::array<int32_t, 3> dir;
    const DenseLight light = lightBase(f, b, dir);
    const LiftedBase lifted(g, light, o.precision, o.input + " grid " + baseName(b));
    for (uint64_t k = 0; k < g.bricks; ++k) anyLight[k] |= lifted.nonEmpty()[k];
    s.active[b] = light.activeVoxels;
    s.peaks[b] = lifted.valueMax();
    for (size_t t = 0; t < nt; ++t) {
      const BaseCode c = lifted.encode(o.thresholds[t]);
      s.stats[t][b] = SweepCell{c.coefBytes(o.precision), c.maxError, c.sumSqError,
                                std::sqrt(c.sumSqError / (3.0 * double(g.cells))), lifted.valueMax()};
    }
    progress.add();
  }
  progress.done();
  for (uint8_t v : anyLight) s.slots += v;
  return s;
}

// The plot's title, axes and empty series.
SweepPlot sweepPlot(const SweepOptions& o, size_t nb) {
  SweepPlot p;
  PlotSpec& plot = p.plot;
  plot.title = "canopy-haar sweep: " + o.input.substr(o.input.find_last_of('/') + 1) + " (" +
               precisionName(o.precision) + ", " + std::to_string(nb) + " bases)";
  plot.xLabel = "RMS error (volume, relative to the peak value)";
  plot.yLabel = "compression ratio vs dense fp32";
  plot.logX = plot.logY = true;
  PlotSeries& overallS = p.overall;
  overallS.label = "all bases (whole file)";
  overallS.color = {200, 40, 40};
  overallS.width = 3.5f;
  overallS.markers = true;
  std::vector<PlotSeries>& baseS = p.bases;
  baseS.resize(nb);
  for (uint32_t b = 0; b < nb; ++b) {
    baseS[b].color = {150, 160, 185};
    baseS[b].width = 1.2f;
    baseS[b].label = b == 0 ? "each base B00..B" + std::to_string(nb - 1) : "";
  }
  return p;
}

// The CSV and JSON rows of every base at threshold t, and its plot points; returns the sums.
SweepTotals sweepBaseRows(const SweepOptions& o, const SweepStats& s, size_t t, uint64_t dense, std::ostringstream& csv,
                          nlohmann::json& rows, std::vector<PlotSeries>& baseS) {
  SweepTotals sum;
  const size_t nb = s.active.size();
  for (uint32_t b = 0; b < nb; ++b) {
    const SweepCell& c = s.stats[t][b];
    const uint64_t bytes = uint64_t(s.slots) * recordBytes(o.precision) + c.coefBytes;
    const double psnr = psnrOf(c.peak, c.rms);
    char line[256];
    std::snprintf(line, sizeof line, "%.9g,%s,%llu,%.6g,%.6g,%.9g,%.9g,%s\n", o.thresholds[t],
                  baseName(b).c_str(), (unsigned long long)bytes, double(dense) / bytes,
                  double(s.active[b] * 12) / bytes, c.maxErr, c.rms,
                  std::isfinite(psnr) ? std::to_string(psnr).c_str() : "inf");
    csv << line;
    rows.push_back({{"threshold", o.thresholds[t]}, {"base", baseName(b)}, {"bytes", bytes},
                    {"ratio_dense", double(dense) / bytes}, {"ratio_sparse", double(s.active[b] * 12) / bytes},
                    {"max_error", c.maxErr}, {"rms_error", c.rms}, {"psnr_db", numberOrNull(psnr)}});
    sum.totalCoefBytes += c.coefBytes;
    sum.sparse += s.active[b] * 12;
    sum.maxErr = std::max(sum.maxErr, c.maxErr);
    sum.sumSq += c.sumSq;
    sum.peak = std::max(sum.peak, c.peak);
    if (c.peak > 0 && c.rms > 0) {
      baseS[b].x.push_back(c.rms / c.peak);
      baseS[b].y.push_back(double(dense) / bytes);
    }
  }
  return sum;
}

// The CSV and JSON row of the whole file at threshold t, its plot point (or note) and log line.
void sweepFileRow(const SweepOptions& o, const LatticeGeom& g, size_t nb, uint32_t slots, size_t t, uint64_t dense,
                  const SweepTotals& sum, std::ostringstream& csv, nlohmann::json& rows, SweepPlot& p) {
  // The META text compressLight would write for this threshold: the size is exact.
  const std::string meta =
      metaJson(o.input, {{"precision", precisionName(o.precision)}, {"threshold", o.thresholds[t]}});
  const uint64_t file = chaarFileSize(uint32_t(nb), g.bricks, slots, sum.totalCoefBytes, o.precision, meta.size());
  const double rms = std::sqrt(sum.sumSq / (3.0 * double(g.cells) * nb));
  const double psnr = psnrOf(sum.peak, rms);
  char line[256];
  std::snprintf(line, sizeof line, "%.9g,all,%llu,%.6g,%.6g,%.9g,%.9g,%s\n", o.thresholds[t],
                (unsigned long long)file, double(dense * nb) / file, double(sum.sparse) / file, sum.maxErr, rms,
                std::isfinite(psnr) ? std::to_string(psnr).c_str() : "inf");
  csv << line;
  rows.push_back({{"threshold", o.thresholds[t]}, {"base", "all"}, {"bytes", file},
                  {"ratio_dense", double(dense * nb) / file}, {"ratio_sparse", double(sum.sparse) / file},
                  {"max_error", sum.maxErr}, {"rms_error", rms}, {"psnr_db", numberOrNull(psnr)}});
  char lbl[64];
  std::snprintf(lbl, sizeof lbl, "T=%g", o.thresholds[t]);
  if (sum.peak > 0 && rms > 0) {
    p.overall.x.push_back(rms / sum.peak);
    p.overall.y.push_back(double(dense * nb) / file);
    p.overall.pointLabels.push_back(lbl);
  } else {
    char note[160];
    std::snprintf(note, sizeof note, "T=%g: lossless (RMS 0), ratio %.2fx (not on the log axis)",
                  o.thresholds[t], double(dense * nb) / file);
    p.plot.notes.push_back(note);
  }
  logInfo("canopy-haar: threshold " + std::string(lbl + 2) + ": file " + fmtBytes(file) + ", ratio " +
          std::to_string(double(dense * nb) / file) + "x, RMS " + std::to_string(rms) + ", max " +
          std::to_string(sum.maxErr));
}

}  // namespace

nlohmann::json sweepThresholds(const SweepOptions& o) {
  const auto t0 = std::chrono::steady_clock::now();
  checkSweepOptions(o);
  AtomicOutput csvOut(o.prefix + ".csv"), jsonOut(o.prefix + ".json");
  LightFieldPtr f = openLightField(o.input);
  const LatticeGeom& g = f->geom;
  const size_t nt = o.thresholds.size(), nb = f->grids.size();
  const SweepStats stats = measureSweep(o, *f);
  const uint64_t dense = g.cells * 12;

  std::ostringstream csv;
  csv << "threshold,base,bytes,ratio_dense,ratio_sparse,max_error,rms_error,psnr_db\n";
  nlohmann::json rows = nlohmann::json::array();
  SweepPlot p = sweepPlot(o, nb);
  for (size_t t = 0; t < nt; ++t) {
    const SweepTotals sum = sweepBaseRows(o, stats, t, dense, csv, rows, p.bases);
    sweepFileRow(o, g, nb, stats.slots, t, dense, sum, csv, rows, p);
  }
  for (auto& s : p.bases) p.plot.series.push_back(s);
  p.plot.series.push_back(p.overall);
  p.plot.notes.push_back("labels: threshold T of each point");

  nlohmann::json rep = {{"input", o.input}, {"precision", precisionName(o.precision)},
                        {"thresholds", o.thresholds}, {"rows", rows},
                        {"outputs", {o.prefix + ".csv", o.prefix + ".json", o.prefix + ".png"}}};
  writeTemp(csvOut, csv.str());
  writeTemp(jsonOut, rep.dump(2) + "\n");
  writePlotPng(o.prefix + ".png", p.plot);
  csvOut.commit();
  jsonOut.commit();
  rep["seconds"] = secondsSince(t0);
  return rep;
}

}  // namespace canopy::haar
