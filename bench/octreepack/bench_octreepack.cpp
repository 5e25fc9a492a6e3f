// bench_octreepack.cpp: pack time, file size and resident part for plants and a >= 400 instance
// forest (a benchmark, not a test: it prints a Markdown table; numbers go to RESULTS.part.md).
//
//   bench-octreepack WORKDIR [PLANT.density.vdb ...] [--instances N]
//
// Plants: every density VDB given (e.g. the shared plants voxelized by canopy-voxelize), else
// synthetic plants (tests/octreepack/synthetic.h: a leafy shell with holes, a trunk and a uniform
// core) at 128, 192 and 256 cells. Forest: pipelines/scatter.py places N (default 400) instances of
// those plants on a 60 m disk; the scene is packed with canopy-octreepack's core in-process.
// A last row packs the largest plant with 19-base lighting (analytic field, in-process).
// Reference in the same run: the bytes of the source density VDBs (OpenVDB, zlib-compressed) next
// to the .canopy, i.e. what streaming-ready layout costs over the compact interchange file.
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <iostream>
#include <sstream>
#include <string>
#include <vector>


#include "canopy/atomic_file.h"
#include "canopy/cli.h"
#include "tests/octreepack/source_vdb.h"
#include "tests/octreepack/synthetic.h"
#include "formats/canopy_write.h"
#include "tools/octreepack/inputs.h"
#include "tools/octreepack/octreepack.h"
#include "../bench_usage.h"

namespace op = canopy::octreepack;

namespace {

uint64_t fileBytes(const std::string& p) { return canopy::readFile(p).size(); }

struct Row {
  std::string name;
  uint64_t cells, instances, vdbBytes, fileBytes, residentBytes, bricks, pages;
  double seconds;
};

Row pack(const std::string& name, const op::OctreepackOptions& o, uint64_t vdbBytes) {
  const auto t0 = std::chrono::steady_clock::now();
  const nlohmann::json r = op::octreepack(o);
  Row row{name, r["occupied_cells"].get<uint64_t>(), r["instances"].get<uint64_t>(), vdbBytes,
          r["file_bytes"].get<uint64_t>(), r["resident_bytes"].get<uint64_t>(), 0, r["pages"].get<uint64_t>(),
          canopy::secondsSince(t0)};
  for (const auto& m : r["models"]) row.bricks += m["bricks"].get<uint64_t>();
  return row;
}

}  // namespace

constexpr char kUsage[] =
    "usage: bench-octreepack WORKDIR [PLANT.density.vdb ...] [--instances N]\n"
    "  Pack time, file size and resident part of plants (synthetic ones without PLANT arguments) and of a\n"
    "  scattered forest of N instances (default 400); Markdown on stdout.\n";

int main(int argc, char** argv) {
  if (benchHelpRequested(argc, argv, kUsage)) return 0;
  if (argc < 2) return benchUsageError("bench-octreepack", "no WORKDIR", kUsage);
  canopy::setQuiet(true);
  const std::string work = argv[1];
  std::vector<std::string> plants;
  int instances = 400;
  for (int i = 2; i < argc; ++i) {
    const std::string a = argv[i];
    if (a == "--instances" && i + 1 < argc) instances = std::atoi(argv[++i]);
    else if (a.size() > 1 && a[0] == '-') return benchUsageError("bench-octreepack", ("unknown option " + a).c_str(), kUsage);
    else plants.push_back(a);
  }
  if (work.empty() || work[0] == '-') return benchUsageError("bench-octreepack", ("bad WORKDIR " + work).c_str(), kUsage);
  std::error_code mkdirError;
  std::filesystem::create_directories(work, mkdirError);
  if (mkdirError) {
    std::cerr << "bench-octreepack: " << work << ": cannot create (" << mkdirError.message() << ")\n";
    return 2;
  }
  try {
    if (plants.empty()) {
      for (int edge : {128, 192, 256}) {
        const std::string name = "synthetic" + std::to_string(edge);
        const std::string path = work + "/" + name + ".density.vdb";
        {
          const op::ModelSource plant = op::testing::syntheticPlant(edge, 0, name.c_str(), edge / 16);
          op::testing::writeSourceVdb(path, plant, plant.sourceLabel);  // as canopy-voxelize writes it
        }
        plants.push_back(path);
      }
    }
    std::vector<Row> rows;
    uint64_t vdbTotal = 0;
    std::string modelArgs;
    for (const std::string& p : plants) {
      op::OctreepackOptions o;
      o.inputs = {p};
      const std::string stem = p.substr(p.find_last_of('/') + 1);
      o.output = work + "/" + stem + ".canopy";
      const uint64_t vb = fileBytes(p);
      vdbTotal += vb;
      rows.push_back(pack(stem, o, vb));
      modelArgs += " --model '" + stem + "=" + p + "'";
    }
    const std::string scene = work + "/forest.scene.json";
    const std::string cmd = "python3 '" + std::string(CANOPY_SOURCE_DIR) + "/pipelines/scatter.py' -o '" + scene + "' --count " +
                            std::to_string(instances) + " --seed 1 --radius 60" + modelArgs + " 2>/dev/null";
    if (std::system(cmd.c_str()) != 0) throw canopy::runtimeError("scatter.py failed: " + cmd);
    op::OctreepackOptions o;
    o.scene = scene;
    o.output = work + "/forest.canopy";
    rows.push_back(pack("forest (" + std::to_string(instances) + " instances)", o, vdbTotal));

    // Lighting: the largest plant again with 19-base lighting from an analytic field (in-process
    // build + write: the lbsolve light VDB reader only adds its grid lookups to this).
    {
      const std::string p = plants.back();
      op::ModelSource src = op::readDensityVdb(p, "lit");
      const auto t0 = std::chrono::steady_clock::now();
      const op::BuiltModel m = op::buildOctree(src, p, op::testing::analyticLight);
      canopy::CanopyWriteInput in;
      in.models.push_back({m.record, &m.tiles, &m.bricks, &m.light});
      in.instances.push_back(canopy::CanopyInstance{});
      const std::string out = work + "/lit.canopy";
      const canopy::CanopyWriteStats st = canopy::writeCanopyFile(out, std::move(in));
      rows.push_back({p.substr(p.find_last_of('/') + 1) + " + light (19 bases)", m.occupiedCells, 1, fileBytes(p), st.fileBytes,
                      st.residentBytes, m.record.brickCount, st.pageCount, canopy::secondsSince(t0)});
    }

    std::ostringstream md;
    md << "| input | occupied cells | instances | source VDB bytes | .canopy bytes | .canopy / VDB | resident bytes | resident % | bricks | pages | pack s |\n"
       << "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|\n";
    for (const Row& r : rows) {
      char buf[512];
      std::snprintf(buf, sizeof buf, "| %s | %llu | %llu | %llu | %llu | %.2f | %llu | %.3f | %llu | %llu | %.2f |\n", r.name.c_str(),
                    (unsigned long long)r.cells, (unsigned long long)r.instances, (unsigned long long)r.vdbBytes,
                    (unsigned long long)r.fileBytes, double(r.fileBytes) / double(r.vdbBytes), (unsigned long long)r.residentBytes,
                    100.0 * double(r.residentBytes) / double(r.fileBytes), (unsigned long long)r.bricks, (unsigned long long)r.pages,
                    r.seconds);
      md << buf;
    }
    std::cout << md.str();
  } catch (const canopy::Error& e) {
    std::cerr << "bench-octreepack: error: " << e.what() << "\n";
    return int(e.code());
  }
  return 0;
}
