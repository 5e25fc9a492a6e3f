// bench_voxelize: times canopy::voxelize on a mesh (default oak_medium.glb, 128^3 x 8) and, on the
// same triangles written as OBJ, OpenVDB's `vdb_tool -read mesh.obj -mesh2ls voxel=H` at
// (a) the fine voxel size (the grid Canopy rasterises: 1024^3 for 128 x 8) and (b) the lattice
// voxel size; prints medians and the ratios (vdb_tool time / Canopy time).
//
//   bench_voxelize [mesh] [--resolution N] [--supersample S] [--repeats R] [--vdb-tool PATH]
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <iostream>
#include <string>
#include <vector>

#include <tbb/info.h>

#include "canopy/cli.h"
#include "voxelize.h"

namespace {

double median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v[v.size() / 2];
}

template <class F>
std::vector<double> timeIt(int repeats, F&& f) {
  std::vector<double> t;
  for (int i = 0; i < repeats; ++i) {
    const auto t0 = std::chrono::steady_clock::now();
    f();
    t.push_back(canopy::secondsSince(t0));
  }
  return t;
}

void writeObj(const canopy::mesh::Mesh& m, const std::string& path) {
  std::ofstream f(path);
  f.precision(9);
  for (const auto& t : m.triangles)
    for (const auto& p : t.p) f << "v " << p[0] << ' ' << p[1] << ' ' << p[2] << '\n';
  for (size_t i = 0; i < m.triangles.size(); ++i)
    f << "f " << 3 * i + 1 << ' ' << 3 * i + 2 << ' ' << 3 * i + 3 << '\n';
}

}  // namespace

int main(int argc, char** argv) {
  std::string input = std::string(CANOPY_SHARED_DIR) + "/assets/plants/oak_medium.glb";
  std::string vdbTool = "vdb_tool";
  int resolution = 128, supersample = 8, repeats = 5;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    auto next = [&] { return i + 1 < argc ? std::string(argv[++i]) : std::string(); };
    if (a == "--resolution") resolution = std::stoi(next());
    else if (a == "--supersample") supersample = std::stoi(next());
    else if (a == "--repeats") repeats = std::max(1, std::stoi(next()));
    else if (a == "--vdb-tool") vdbTool = next();
    else input = a;
  }
  canopy::setQuiet(true);
  canopy::VoxelizeOptions o;
  o.input = input;
  o.resolution = resolution;
  o.supersample = supersample;
  try {
    // Canopy: load + clean + rasterise + average (in memory), and the same plus writing the .vdb.
    canopy::VoxelizeResult r;
    const auto tCompute = timeIt(repeats, [&] { r = canopy::voxelize(o); });
    char tmpl[] = "/tmp/canopy-bench-XXXXXX";
    const std::string dir = mkdtemp(tmpl);
    o.output = dir + "/canopy.vdb";
    const auto tWrite = timeIt(repeats, [&] { canopy::voxelize(o); });
    const canopy::mesh::Mesh mesh = canopy::mesh::loadMesh(input);
    const std::string obj = dir + "/mesh.obj";
    writeObj(mesh, obj);
    const double hLattice = r.frame.voxelSize, hFine = hLattice / supersample;
    auto vdbToolRun = [&](double h) {
      const std::string cmd = vdbTool + " -read '" + obj + "' -mesh2ls voxel=" + std::to_string(h) +
                              " width=3 -write '" + dir + "/vdbtool.vdb' > /dev/null 2>&1";
      return timeIt(repeats, [&] {
        if (std::system(cmd.c_str()) != 0) throw std::runtime_error("vdb_tool failed: " + cmd);
      });
    };
    // vdb_tool's own OBJ parse time, to subtract: read + write of the mesh alone is not possible
    // (no grid), so the read is timed with an empty conversion at a huge voxel size.
    const auto tToolFine = vdbToolRun(hFine);
    const auto tToolLattice = vdbToolRun(hLattice);
    const auto tToolRead = vdbToolRun(hLattice * 64);
    std::system(("rm -rf '" + dir + "'").c_str());

    const double cC = median(tCompute), cW = median(tWrite);
    const double vF = median(tToolFine), vL = median(tToolLattice), vR = median(tToolRead);
    std::printf("mesh            %s (%zu triangles)\n", input.c_str(), mesh.triangles.size());
    std::printf("threads         %d (TBB default concurrency), repeats %d, medians\n",
                tbb::info::default_concurrency(), repeats);
    std::printf("lattice         %d^3 x %d supersampling: fine grid %d^3, voxel %.6g m, fine voxel %.6g m\n",
                resolution, supersample, resolution * supersample, hLattice, hFine);
    std::printf("occupied cells  %zu, fine touches %llu, exact tests %llu\n", r.cells.size(),
                (unsigned long long)r.stats.fineTouches, (unsigned long long)r.stats.exactTests);
    std::printf("canopy-voxelize compute %.3f s (load %.3f, clean %.3f, voxelize %.3f); with .vdb write %.3f s\n",
                cC, r.stats.secondsLoad, r.stats.secondsClean, r.stats.secondsVoxelize, cW);
    std::printf("vdb_tool -mesh2ls at fine voxel    %.3f s   ratio vdb_tool/canopy = %.2f\n", vF, vF / cW);
    std::printf("vdb_tool -mesh2ls at lattice voxel %.3f s   ratio vdb_tool/canopy = %.2f\n", vL, vL / cW);
    std::printf("vdb_tool read+tiny grid (overhead) %.3f s\n", vR);
    return 0;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "bench_voxelize: %s\n", e.what());
    return 1;
  }
}
