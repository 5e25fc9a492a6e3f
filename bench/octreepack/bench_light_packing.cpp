// bench_light_packing.cpp: what the packed file's lighting costs and how exact it is, per Haar
// threshold (a benchmark, not a test: it prints a Markdown table for bench/RESULTS.md).
//
//   bench-light-packing WORKDIR PLANT.density.vdb PLANT.light.vdb [--thresholds 0,0.003,...]
//                       [--precision fp16|fp32]
//
// For each threshold T: canopy-haar PLANT.light.vdb --threshold T -> .chaar, canopy-octreepack
// packs it (format 4.0: light items of the decoded values on every level, and the .chaar's
// bricks as Haar pages) and, for reference, the uncompressed light VDB (light items only).
// Reported per packed file: the bytes of its light item pages and of its Haar pages, and the
// error of the finest level's light against canopy-lbsolve's values (the light VDB) at every
// occupied lattice cell, all 19 bases x RGB, as canopy-play samples it with --light fast (the
// light items, canopySampleLight) and --light exact (the Haar pages, canopyHaarSampleAt): RMS and
// max absolute, relative to the largest value. The tools are run from the folder of this executable.
#include <unistd.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <iostream>
#include <sstream>
#include <string>
#include <vector>

#include "canopy/atomic_file.h"
#include "canopy/cli.h"
#include "formats/canopy_file.h"
#include "tests/octreepack/packed_sampler.h"
#include "tools/octreepack/inputs.h"
#include "../bench_usage.h"

namespace op = canopy::octreepack;

namespace {

struct Err {
  double sumSq = 0, max = 0, peak = 0;
  uint64_t n = 0;
};

// The finest level's light of the packed model 0 at every occupied cell vs the truth, from the
// Haar pages (haar) or the light items: [0] all 19 bases, [1] the sun bases B01..B18 alone (with
// their own peak: lbsolve stores them without their direct beam, far smaller than B00).
std::array<Err, 2> lightError(const canopy::CanopyFile& f, const op::ModelSource& src, const op::LightFn& truth, bool haar) {
  op::testing::PackedSampler S(f);
  const canopy::CanopyModel& M = f.model(0);
  std::array<Err, 2> errs;
  float want[canopy::kCanopyLightChannels];
  for (const op::SourceCell& c : src.cells) {
    truth(c.ijk[0], c.ijk[1], c.ijk[2], want);
    float u[3];
    canopy::canopyLatticeToUnit(M.octreeOrigin, M.rootCells, float(c.ijk[0]), float(c.ijk[1]), float(c.ijk[2]), u);
    const canopy::CanopyLookup r = f.descend(0, u[0], u[1], u[2], M.depth);
    for (uint32_t b = 0; b < canopy::kCanopyLightBases; ++b) {
      float got[3] = {0, 0, 0};
      if (haar) {
        const canopy::haar::Rgb v = S.sampleHaar(0, b, float(c.ijk[0]), float(c.ijk[1]), float(c.ijk[2]));
        got[0] = v.r, got[1] = v.g, got[2] = v.b;
      } else if (r.node.brick != canopy::kCanopyNone) {
        const auto& page = S.pageData(canopy::canopyLightPage(M, r.node.brick, f.header().lightItemsPerPage));
        canopy::canopySampleLight(canopy::canopyLightInPage(page.data(), r.node.brick % f.header().lightItemsPerPage), b, r.local[0],
                                  r.local[1], r.local[2], got);
      }
      for (int ch = 0; ch < 3; ++ch) {
        const double w = want[3 * b + size_t(ch)], d = double(got[ch]) - w;
        for (Err* e : {&errs[0], b > 0 ? &errs[1] : nullptr}) {
          if (!e) continue;
          e->sumSq += d * d;
          e->max = std::max(e->max, std::fabs(d));
          e->peak = std::max(e->peak, std::fabs(w));
          ++e->n;
        }
      }
    }
  }
  return errs;
}



int run(const std::string& cmd) {
  const int rc = std::system(cmd.c_str());
  if (rc != 0) std::cerr << "bench-light-packing: failed (" << rc << "): " << cmd << "\n";
  return rc;
}

std::string q(const std::string& s) { return "'" + s + "'"; }

}  // namespace

constexpr char kUsage[] =
    "usage: bench-light-packing WORKDIR PLANT.density.vdb PLANT.light.vdb [--thresholds T,T,...] [--precision fp16|fp32]\n"
    "  Bytes and error of a plant's packed light per Haar threshold; Markdown on stdout.\n";

int main(int argc, char** argv) {
  if (benchHelpRequested(argc, argv, kUsage)) return 0;
  if (argc < 4) return benchUsageError("bench-light-packing", "expected WORKDIR PLANT.density.vdb PLANT.light.vdb", kUsage);
  canopy::setQuiet(true);
  const std::string work = argv[1], density = argv[2], lightVdb = argv[3];
  std::string thresholds = "0,0.003,0.01,0.03,0.1", precision = "fp16";
  for (int i = 4; i < argc; i += 2) {
    const std::string a = argv[i];
    if (i + 1 >= argc) return benchUsageError("bench-light-packing", ("no value after " + a).c_str(), kUsage);
    if (a == "--thresholds") thresholds = argv[i + 1];
    else if (a == "--precision") precision = argv[i + 1];
    else {
      return benchUsageError("bench-light-packing", ("unknown option " + a).c_str(), kUsage);
    }
  }
  std::string bin = argv[0];  // the tools beside this executable (also when it was found on PATH)
  {
    char self[4096];
    const ssize_t n = readlink("/proc/self/exe", self, sizeof self - 1);
    if (n > 0) bin.assign(self, size_t(n));
    bin = bin.find('/') == std::string::npos ? std::string(".") : bin.substr(0, bin.rfind('/'));
  }
  if (run("mkdir -p " + q(work)) != 0) return 2;
  try {
    const op::ModelSource src = op::readDensityVdb(density, "plant");
    const op::LightVdb truth = op::readLightVdb(lightVdb, src);
    struct Row {
      std::string scheme;
      uint64_t chaarBytes, fileBytes, itemBytes, haarBytes;
      std::array<Err, 2> fast, exact;
      bool hasHaar;
    };
    std::vector<Row> rows;
    auto packAndMeasure = [&](const std::string& scheme, const std::string& lightIn, uint64_t chaarBytes) {
      const std::string out = work + "/plant." + std::to_string(rows.size()) + ".canopy";
      if (run(q(bin + "/canopy-octreepack") + " -q " + q(density) + " " + q(lightIn) + " -o " + q(out)) != 0) std::exit(3);
      const canopy::CanopyFile f = canopy::CanopyFile::open(out);
      const canopy::CanopyModel& M = f.model(0);
      const bool hasHaar = (M.flags & canopy::kCanopyModelHaarLight) != 0;
      rows.push_back({scheme, chaarBytes, f.header().fileBytes, uint64_t(M.lightPageCount) * f.header().pageBytes,
                      uint64_t(M.haarPageCount) * f.header().pageBytes, lightError(f, src, truth.fn, false),
                      hasHaar ? lightError(f, src, truth.fn, true) : std::array<Err, 2>{}, hasHaar});
    };
    packAndMeasure("light VDB (light items only)", lightVdb, 0);
    std::stringstream ts(thresholds);
    for (std::string t; std::getline(ts, t, ',');) {
      const std::string chaar = work + "/plant.T" + t + "." + precision + ".chaar";
      if (run(q(bin + "/canopy-haar") + " -q " + q(lightVdb) + " --threshold " + t + " --precision " + precision + " -o " + q(chaar)) != 0)
        return 3;
      packAndMeasure(".chaar " + precision + ", threshold " + t, chaar, canopy::readFile(chaar).size());
    }
    const canopy::CanopyFile plain = [&] {
      const std::string out = work + "/plant.density-only.canopy";
      if (run(q(bin + "/canopy-octreepack") + " -q " + q(density) + " -o " + q(out)) != 0) std::exit(3);
      return canopy::CanopyFile::open(out);
    }();
    std::printf("Light of %s (%zu occupied cells) packed with %s (density only: %.2f MB):\n\n", lightVdb.c_str(), src.cells.size(),
                density.c_str(), double(plain.header().fileBytes) / 1e6);
    for (int part = 0; part < 2; ++part) {
      std::printf("%s\n\n", part == 0 ? "All 19 bases:" : "The sun bases B01..B18 alone (relative to their own peak):");
      std::printf("| lighting input | .chaar MB | .canopy MB | light item pages MB | Haar pages MB | fast (items): RMS / peak | max / peak | exact (Haar): RMS / peak | max / peak |\n");
      std::printf("|---|---:|---:|---:|---:|---:|---:|---:|---:|\n");
      for (const Row& r : rows) {
        auto rel = [](const Err& e, bool rmsOf) {
          const double v = rmsOf ? std::sqrt(e.sumSq / double(std::max<uint64_t>(e.n, 1))) : e.max;
          char buf[32];
          std::snprintf(buf, sizeof buf, "%.2e", e.peak > 0 ? v / e.peak : 0.0);
          return std::string(buf);
        };
        const Err& fast = r.fast[size_t(part)];
        const Err& exact = r.exact[size_t(part)];
        std::printf("| %s | %s | %.2f | %.2f | %.2f | %s | %s | %s | %s |\n", r.scheme.c_str(),
                    r.chaarBytes ? std::to_string(double(r.chaarBytes) / 1e6).substr(0, 5).c_str() : "-", double(r.fileBytes) / 1e6,
                    double(r.itemBytes) / 1e6, double(r.haarBytes) / 1e6, rel(fast, true).c_str(), rel(fast, false).c_str(),
                    r.hasHaar ? rel(exact, true).c_str() : "-", r.hasHaar ? rel(exact, false).c_str() : "-");
      }
      std::printf("\npeak value (largest |light| at an occupied cell): %.4g\n\n", rows.empty() ? 0.0 : rows[0].fast[size_t(part)].peak);
    }
  } catch (const canopy::Error& e) {
    std::cerr << "bench-light-packing: " << e.what() << "\n";
    return int(e.code());
  }
  return 0;
}
