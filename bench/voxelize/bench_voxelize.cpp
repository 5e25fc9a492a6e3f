// bench_voxelize: times canopy::voxelize on a mesh (default oak_medium.glb, 128^3 x 8) and, on the
// same triangles written as OBJ, OpenVDB's `vdb_tool -read mesh.obj -mesh2ls voxel=H` at
// (a) the fine voxel size (the grid Canopy rasterises: 1024^3 for 128 x 8) and (b) the lattice
// voxel size; prints medians and the ratios (vdb_tool time / Canopy time).
//
//   bench_voxelize [mesh] [--resolution N] [--supersample S] [--repeats R] [--vdb-tool PATH]
#include <sys/resource.h>
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
#include "../bench_usage.h"

namespace {

double median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v[v.size() / 2];
}

// CPU seconds (user + system) of this process or of its waited-for children.
double cpuSeconds(int who) {
  rusage u;
  getrusage(who, &u);
  return double(u.ru_utime.tv_sec + u.ru_stime.tv_sec) + 1e-6 * double(u.ru_utime.tv_usec + u.ru_stime.tv_usec);
}

// Wall-clock seconds per run; cpu (if given) receives the median CPU seconds per run.
template <class F>
std::vector<double> timeIt(int repeats, F&& f, double* cpu = nullptr, int who = RUSAGE_SELF) {
  std::vector<double> t, c;
  for (int i = 0; i < repeats; ++i) {
    const double c0 = cpuSeconds(who);
    const auto t0 = std::chrono::steady_clock::now();
    f();
    t.push_back(canopy::secondsSince(t0));
    c.push_back(cpuSeconds(who) - c0);
  }
  if (cpu) *cpu = median(c);
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

constexpr char kUsage[] =
    "usage: bench_voxelize [MESH] [--resolution 128] [--supersample 8] [--repeats 5] [--vdb-tool vdb_tool]\n"
    "                      [--tool-repeats 1]\n"
    "  Voxelisation time of MESH (default: the shared oak_medium.glb) against OpenVDB's vdb_tool -mesh2ls\n"
    "  on the same triangles.\n";

int main(int argc, char** argv) {
  if (benchHelpRequested(argc, argv, kUsage)) return 0;
  std::string input = std::string(CANOPY_SHARED_DIR) + "/assets/plants/oak_medium.glb";
  std::string vdbTool = "vdb_tool";
  int resolution = 128, supersample = 8, repeats = 5, toolRepeats = 1;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    auto next = [&] { return i + 1 < argc ? std::string(argv[++i]) : std::string(); };
    if (a == "--resolution") resolution = std::stoi(next());
    else if (a == "--supersample") supersample = std::stoi(next());
    else if (a == "--repeats") repeats = std::max(1, std::stoi(next()));
    else if (a == "--vdb-tool") vdbTool = next();
    else if (a == "--tool-repeats") toolRepeats = std::max(1, std::stoi(next()));
    else if (a.size() > 1 && a[0] == '-') return benchUsageError("bench_voxelize", ("unknown option " + a).c_str(), kUsage);
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
    double cpuCompute = 0, cpuWrite = 0, cpuFine = 0, cpuLattice = 0, cpuRead = 0;
    const auto tCompute = timeIt(repeats, [&] { r = canopy::voxelize(o); }, &cpuCompute);
    char tmpl[] = "/tmp/canopy-bench-XXXXXX";
    const std::string dir = mkdtemp(tmpl);
    o.output = dir + "/canopy.vdb";
    const auto tWrite = timeIt(repeats, [&] { canopy::voxelize(o); }, &cpuWrite);
    const canopy::mesh::Mesh mesh = canopy::mesh::loadMesh(input);
    const std::string obj = dir + "/mesh.obj";
    writeObj(mesh, obj);
    const double hLattice = r.frame.voxelSize, hFine = hLattice / supersample;
    auto vdbToolRun = [&](double h, double* cpu) {
      const std::string cmd = vdbTool + " -read '" + obj + "' -mesh2ls voxel=" + std::to_string(h) +
                              " width=3 -write '" + dir + "/vdbtool.vdb' > /dev/null 2>&1";
      return timeIt(toolRepeats, [&] {
        if (std::system(cmd.c_str()) != 0) throw std::runtime_error("vdb_tool failed: " + cmd);
      }, cpu, RUSAGE_CHILDREN);
    };
    // vdb_tool's own OBJ parse time, to subtract: read + write of the mesh alone is not possible
    // (no grid), so the read is timed with an empty conversion at a huge voxel size.
    const auto tToolFine = vdbToolRun(hFine, &cpuFine);
    const auto tToolLattice = vdbToolRun(hLattice, &cpuLattice);
    const auto tToolRead = vdbToolRun(hLattice * 64, &cpuRead);
    std::system(("rm -rf '" + dir + "'").c_str());

    const double cC = median(tCompute), cW = median(tWrite);
    const double vF = median(tToolFine), vL = median(tToolLattice), vR = median(tToolRead);
    std::printf("mesh            %s (%zu triangles)\n", input.c_str(), mesh.triangles.size());
    std::printf("threads         %d (TBB default concurrency); medians of %d (canopy), %d (vdb_tool) runs\n",
                tbb::info::default_concurrency(), repeats, toolRepeats);
    std::printf("lattice         %d^3 x %d supersampling: fine grid %d^3, voxel %.6g m, fine voxel %.6g m\n",
                resolution, supersample, resolution * supersample, hLattice, hFine);
    std::printf("occupied cells  %zu, fine touches %llu, exact tests %llu\n", r.cells.size(),
                (unsigned long long)r.stats.fineTouches, (unsigned long long)r.stats.exactTests);
    std::printf("                                    wall s    cpu s   (cpu = user+sys, all threads)\n");
    std::printf("canopy-voxelize in memory           %7.3f  %7.3f   (last run: load %.3f, clean %.3f, voxelize %.3f)\n",
                cC, cpuCompute, r.stats.secondsLoad, r.stats.secondsClean, r.stats.secondsVoxelize);
    std::printf("canopy-voxelize incl. .vdb write    %7.3f  %7.3f\n", cW, cpuWrite);
    std::printf("vdb_tool -mesh2ls, fine voxel       %7.3f  %7.3f   ratio vdb_tool/canopy: wall %.2f, cpu %.2f\n",
                vF, cpuFine, vF / cW, cpuFine / cpuWrite);
    std::printf("vdb_tool -mesh2ls, lattice voxel    %7.3f  %7.3f   ratio vdb_tool/canopy: wall %.2f, cpu %.2f\n",
                vL, cpuLattice, vL / cW, cpuLattice / cpuWrite);
    std::printf("vdb_tool read + tiny grid           %7.3f  %7.3f   (its OBJ parsing and start-up)\n", vR, cpuRead);
    return 0;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "bench_voxelize: %s\n", e.what());
    return 1;
  }
}
