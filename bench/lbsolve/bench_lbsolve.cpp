// bench_lbsolve: throughput of the LB lighting update against the device's copy bandwidth, and the
// wall time of the 57 solves (19 bases x RGB) of one plant. Prints Markdown tables on stdout.
//
//   bench_lbsolve [--device cpu|cuda|cuda:N] [--sizes 128,256] [--solves-sizes 128]
//                 [--iterations 64] [--schemes shift,shift-split,push,pull] [--fill plant|full|plant,full]
//                 [--lattices a.density.vdb,b.density.vdb] [--in-flight 1,2,3] [--boxes 256x128x64,...]
//
// Throughput: K solves in flight on one GPU (--in-flight, CudaRun::solvesPerGpu; 1 by default),
// each run for I/4 and for I iterations (tolerance 0); the difference divided by K x 3I/4 x nodes
// removes fixed costs (initialisation, gathering the result). "Node updates/s" counts
// lattice nodes advanced by one iteration, whatever the scheme does at each node. Bytes per update:
// - push and pull: the nominal traffic of collide.h's push update: 19 floats read + 19 floats
//   written + 4 bytes of coded density = 156 B per node (pull moves the same values, pull_stream.h);
// - shift (shift_stream.h): per iteration, each occupied interior node reads and writes its 19
//   values in place and reads its index and coded density (164 B); each boundary node reads its
//   index and coded density (12 B) and writes one float per direction pointing into the interior;
//   divided by the number of nodes. Empty interior nodes cost nothing.
// Copy bandwidth: a cudaMemcpy device-to-device of 1 GiB, counted as bytes read + bytes written,
// best of 10, measured in the same run (on the CPU: std::memcpy of 1 GiB with all threads, counted
// the same way). The 57-solve wall time uses the tool's defaults (tolerance 1e-4 checked every 16
// iterations, cap 2 x the longest edge) on the chosen device: "cuda" = every GPU. Lattices:
// "plant" is tests/lbsolve/fixtures.h's synthetic plant, "full" the same box with every interior
// node occupied (random density, 10% wood: the most arithmetic per node), "air" nothing occupied,
// --boxes adds non-cubic boxes (NXxNYxNZ: the row length, nx, apart from the node count), and --lattices reads
// canopy-voxelize outputs (e.g. oak_medium at 128^3).
#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

#ifdef CANOPY_HAS_CUDA
#include <cuda_runtime.h>
#endif

#include "canopy/device.h"
#include "canopy/lattice_dirs.h"
#include "canopy/parallel.h"
#include "fixtures.h"
#include "lattice_io.h"
#include "params.h"
#include "solver.h"
#include "../bench_usage.h"

using namespace canopy;
using namespace canopy::lb;

namespace {
using Clock = std::chrono::steady_clock;
double since(Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); }

std::vector<std::string> parseWords(const std::string& s) {
  std::vector<std::string> v;
  std::stringstream ss(s);
  for (std::string item; std::getline(ss, item, ',');)
    if (!item.empty()) v.push_back(item);
  return v;
}

std::vector<int> parseList(const std::string& s) {
  std::vector<int> v;
  for (const auto& w : parseWords(s)) v.push_back(std::stoi(w));
  return v;
}

CudaScheme parseScheme(const std::string& s) {
  for (CudaScheme c : {CudaScheme::Shift, CudaScheme::ShiftSplit, CudaScheme::Push, CudaScheme::Pull})
    if (s == cudaSchemeName(c)) return c;
  throw std::runtime_error("unknown scheme '" + s + "' (shift, shift-split, push, pull)");
}

int64_t occupiedNodes(const DenseLattice& L) {
  int64_t k = 0;
  for (float c : L.coded) k += c != 0.f;
  return k;
}

// Nominal device-memory bytes per lattice node and iteration (see the header comment).
double bytesPerUpdate(const DenseLattice& L, const Device& dev, CudaScheme scheme) {
  if (!dev.isCuda() || scheme == CudaScheme::Push || scheme == CudaScheme::Pull)
    return (2 * kQ + 1) * 4.0;
  const Dims d = L.dims;
  double bytes = 0;
  for (int z = 0; z < d.nz; ++z)
    for (int y = 0; y < d.ny; ++y)
      for (int x = 0; x < d.nx; ++x) {
        const float c = L.coded[size_t(d.index(x, y, z))];
        if (d.interior(x, y, z)) {
          if (c != 0.f) bytes += 2 * kQ * 4 + 8 + 4;
          continue;
        }
        bytes += 8 + 4;
        for (int m = 0; m < kQ; ++m)
          bytes += 4 * d.interior(x + lattice::dir(m, 0), y + lattice::dir(m, 1), z + lattice::dir(m, 2));
      }
  return bytes / double(d.count());
}

// The synthetic plant, or ("full") every interior node occupied.
// A box of nx x ny x nz nodes: "plant" is the synthetic plant of the longest edge cut to the box
// about its centre, "full" every interior node occupied (random density, 10 % wood), "air" nothing
// occupied (the update is then its memory traffic and the collision's empty path).
DenseLattice makeLattice(int nx, int ny, int nz, const std::string& fill) {
  if (fill != "plant" && fill != "full" && fill != "air")
    throw std::runtime_error("unknown fill '" + fill + "' (plant, full, air)");
  const int n = std::max({nx, ny, nz});
  const fixtures::Plant plant = fixtures::makePlant(n);
  const size_t count = size_t(nx) * ny * nz;
  std::vector<float> density(count, 0.f), wood(count, 0.f);
  const int ox = (n - nx) / 2, oy = (n - ny) / 2, oz = (n - nz) / 2;
  for (int z = 0; z < nz; ++z)
    for (int y = 0; y < ny; ++y)
      for (int x = 0; x < nx; ++x) {
        const size_t i = (size_t(z) * ny + y) * nx + x;
        const bool interior = x > 0 && y > 0 && z > 0 && x < nx - 1 && y < ny - 1 && z < nz - 1;
        if (fill == "plant") {
          const size_t j = (size_t(z + oz) * n + size_t(y + oy)) * n + size_t(x + ox);
          density[i] = plant.density[j], wood[i] = plant.wood[j];
        } else if (fill == "full" && interior) {
          density[i] = 0.05f + 0.95f * fixtures::hashUnit(i, 21);
          wood[i] = fixtures::hashUnit(i, 22) < 0.1f ? 1.f : 0.f;
        }
      }
  DenseLattice L = fixtures::denseOf(nx, ny, nz, density, wood);
  L.stored = storedNodes(L.dims, density);
  return L;
}
DenseLattice makeLattice(int n, const std::string& fill) { return makeLattice(n, n, n, fill); }

// "NXxNYxNZ" -> {nx, ny, nz}, each in [3, 4096].
std::array<int, 3> parseBox(const std::string& s) {
  std::array<int, 3> b{};
  char x1 = 0, x2 = 0;
  std::istringstream in(s);
  if (!(in >> b[0] >> x1 >> b[1] >> x2 >> b[2]) || x1 != 'x' || x2 != 'x' || !in.eof())
    throw std::runtime_error("--boxes: '" + s + "' is not NXxNYxNZ");
  for (int v : b)
    if (v < 3 || v > 4096) throw std::runtime_error("--boxes: edges must lie in [3, 4096]");
  return b;
}

SolveSpec baseSpec(int b, int c, int iterations, float tolerance) {
  const LightParams p;
  SolveSpec s;
  s.omega = makeOmegaSet(p.sigmaA[c], p.sigmaS[c], p.g[c], p.gWood, p.beerLambert ? p.sigma : 0.0);
  for (int m = 0; m < kQ; ++m) s.boundary[m] = (b == 0 || m == b) ? 1.f : 0.f;
  s.maxIterations = iterations;
  s.tolerance = tolerance;
  return s;
}

// Copy bandwidth (bytes read + written per second) of the device.
double copyBandwidth(const Device& dev) {
  const size_t bytes = size_t(1) << 30;
#ifdef CANOPY_HAS_CUDA
  if (dev.isCuda()) {
    cudaSetDevice(dev.index < 0 ? 0 : dev.index);
    void *a = nullptr, *b = nullptr;
    if (cudaMalloc(&a, bytes) != cudaSuccess || cudaMalloc(&b, bytes) != cudaSuccess) return 0;
    cudaMemset(a, 1, bytes);
    cudaMemcpy(b, a, bytes, cudaMemcpyDeviceToDevice);
    cudaEvent_t e0, e1;
    cudaEventCreate(&e0);
    cudaEventCreate(&e1);
    float best = 1e30f;
    for (int r = 0; r < 10; ++r) {
      cudaEventRecord(e0);
      cudaMemcpy(b, a, bytes, cudaMemcpyDeviceToDevice);
      cudaEventRecord(e1);
      cudaEventSynchronize(e1);
      float ms = 0;
      cudaEventElapsedTime(&ms, e0, e1);
      best = std::min(best, ms);
    }
    cudaFree(a);
    cudaFree(b);
    return 2.0 * bytes / (best * 1e-3);
  }
#endif
  std::vector<char> a(bytes, 1), b(bytes, 0);
  const int64_t chunks = 256;
  const size_t chunk = bytes / chunks;
  double best = 1e30;
  for (int r = 0; r < 5; ++r) {
    const auto t0 = Clock::now();
    parallelFor(chunks, [&](int64_t i) { std::memcpy(b.data() + i * chunk, a.data() + i * chunk, chunk); }, 1);
    best = std::min(best, since(t0));
  }
  return 2.0 * bytes / best;
}

// K solves of `iterations` each (bases 4.., green), all in flight at once on one GPU.
double solveSeconds(const DenseLattice& L, const Device& dev, const CudaRun& run, int iterations) {
  std::vector<SolveSpec> specs;
  for (int k = 0; k < run.solvesPerGpu; ++k) specs.push_back(baseSpec(4 + k % 15, 1, iterations, 0.f));
  const auto t0 = Clock::now();
  runSolves(L, specs, dev, {}, run);
  return since(t0);
}

// The runs to measure: every scheme x in-flight count.
std::vector<CudaRun> runsOf(const std::vector<CudaScheme>& schemes, const std::vector<int>& inFlight) {
  std::vector<CudaRun> runs;
  for (CudaScheme c : schemes)
    for (int k : inFlight) {
      CudaRun r(c);
      r.solvesPerGpu = k;
      runs.push_back(r);
    }
  return runs;
}
}  // namespace

constexpr char kUsage[] =
    "usage: bench_lbsolve [--device D] [--sizes 128,256] [--solves-sizes 128] [--iterations 64]\n"
    "                     [--schemes shift,shift-split,push,pull] [--fill plant,full]\n"
    "                     [--lattices a.vdb,...] [--in-flight 1,2,3] [--boxes 256x128x64,...]\n"
    "  Dense-update throughput (node updates/s, fraction of the copy bandwidth) and the wall time of\n"
    "  the 57 solves per lattice; Markdown on stdout. Exit 0 ok, 1 usage, 4 failure, 5 no such device.\n";

int main(int argc, char** argv) try {
  if (benchHelpRequested(argc, argv, kUsage)) return 0;
  std::string deviceSpec = "auto";
  std::vector<int> sizes{128, 256}, solveSizes{128};
  std::vector<std::string> schemeNames{"shift"}, fills{"plant"}, lattices, boxes;
  std::vector<int> inFlight{1};
  int iterations = 64;
  for (int i = 1; i < argc; i += 2) {
    const std::string k = argv[i];
    if (i + 1 >= argc) return benchUsageError("bench_lbsolve", ("no value after " + k).c_str(), kUsage);
    const std::string v = argv[i + 1];
    if (k == "--device") deviceSpec = v;
    else if (k == "--sizes") sizes = parseList(v);
    else if (k == "--solves-sizes") solveSizes = parseList(v);
    else if (k == "--iterations") iterations = std::stoi(v);
    else if (k == "--schemes") schemeNames = parseWords(v);
    else if (k == "--fill") fills = parseWords(v);
    else if (k == "--lattices") lattices = parseWords(v);
    else if (k == "--boxes") boxes = parseWords(v);
    else if (k == "--in-flight") inFlight = parseList(v);
    else return benchUsageError("bench_lbsolve", ("unknown option " + k).c_str(), kUsage);
  }
  Device dev;
  try {
    dev = resolveDevice(deviceSpec);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "bench_lbsolve: %s\n", e.what());
    return 5;
  }
  std::vector<CudaScheme> schemes;
  for (const auto& w : schemeNames) schemes.push_back(parseScheme(w));
  if (!dev.isCuda()) schemes = {CudaScheme::Shift};  // the CPU has one scheme (the reference)
  for (int k : inFlight)
    if (k < 1) throw std::runtime_error("--in-flight counts must be >= 1");
  if (!dev.isCuda()) inFlight = {1};
  const std::vector<CudaRun> runs = runsOf(schemes, inFlight);
  auto schemeLabel = [&](const CudaRun& r) {
    if (!dev.isCuda()) return std::string("cpu");
    std::string label = cudaSchemeName(r.scheme);
    if (inFlight.size() > 1 || r.solvesPerGpu > 1) label += " x" + std::to_string(r.solvesPerGpu) + " in flight";
    return label;
  };
  std::string devName = dev.str();
#ifdef CANOPY_HAS_CUDA
  if (dev.isCuda()) {
    cudaDeviceProp prop;
    cudaGetDeviceProperties(&prop, dev.index < 0 ? 0 : dev.index);
    devName += std::string(" (") + prop.name + ", " + std::to_string(cudaDeviceCount()) + " GPU(s) visible)";
  }
#endif
  const Device one = dev.isCuda() ? Device{Device::Kind::Cuda, dev.index < 0 ? 0 : dev.index} : dev;
  const double bw = copyBandwidth(one);
  std::printf("# bench_lbsolve: device %s\n\n", devName.c_str());
  std::printf("copy bandwidth (one device, read+write): %.1f GB/s\n\n", bw / 1e9);
  std::printf("| lattice | scheme | nodes | occupied | node updates/s | bytes/update | GB/s | fraction of copy bandwidth |\n");
  std::printf("|---|---|---|---|---|---|---|---|\n");
  std::vector<std::array<int, 3>> shapes;
  for (int n : sizes) shapes.push_back({n, n, n});
  for (const auto& b : boxes) shapes.push_back(parseBox(b));
  for (const auto& fill : fills)
    for (const auto& shape : shapes) {
      const DenseLattice L = makeLattice(shape[0], shape[1], shape[2], fill);
      const std::string name = shape[0] == shape[1] && shape[1] == shape[2]
                                   ? std::to_string(shape[0]) + "^3"
                                   : std::to_string(shape[0]) + "x" + std::to_string(shape[1]) + "x" + std::to_string(shape[2]);
      const double occupied = double(occupiedNodes(L)) / double(L.dims.count());
      for (const CudaRun& run : runs) {
        solveSeconds(L, one, run, 2);  // warm-up (allocation, first launch)
        const int i1 = std::max(1, iterations / 4), i2 = std::max(i1 + 1, iterations);
        const double t1 = solveSeconds(L, one, run, i1), t2 = solveSeconds(L, one, run, i2);
        // (a run too short to time gives no figure: nan)
        const double rate = t2 > t1 ? double(L.dims.count()) * run.solvesPerGpu * (i2 - i1) / (t2 - t1) : std::nan("");
        const double bytes = bytesPerUpdate(L, one, run.scheme);
        std::printf("| %s %s | %s | %lld | %.1f%% | %.3g | %.1f | %.1f | %.1f%% |\n", fill.c_str(), name.c_str(),
                    schemeLabel(run).c_str(), (long long)L.dims.count(), 100.0 * occupied, rate, bytes,
                    rate * bytes / 1e9, 100.0 * rate * bytes / bw);
        std::fflush(stdout);
      }
    }
  std::printf("\n| lattice | scheme | device | 57 solves wall time | iterations (min..max) | node updates/s |\n");
  std::printf("|---|---|---|---|---|---|\n");
  auto solveAll = [&](const std::string& label, const DenseLattice& L) {
    const int edge = std::max({L.dims.nx, L.dims.ny, L.dims.nz});
    std::vector<SolveSpec> specs;
    for (int b = 0; b < kQ; ++b)
      for (int c = 0; c < 3; ++c) specs.push_back(baseSpec(b, c, 2 * edge, 1e-4f));
    std::vector<Device> devices{dev};
    if (dev.isCuda() && dev.index < 0 && cudaDeviceCount() > 1) devices.insert(devices.begin(), one);
    for (const CudaRun& run : runs)
      for (const Device& d : devices) {
        const auto t0 = Clock::now();
        const auto r = runSolves(L, specs, d, {}, run);
        const double s = since(t0);
        int lo = 1 << 30, hi = 0;
        double updates = 0;
        for (const auto& x : r) {
          lo = std::min(lo, x.iterations);
          hi = std::max(hi, x.iterations);
          updates += double(x.iterations) * L.dims.count();
        }
        const std::string devLabel =
            d.isCuda() && d.index < 0 ? "cuda x" + std::to_string(cudaDeviceCount()) : d.str();
        std::printf("| %s | %s | %s | %.3f s | %d..%d | %.3g |\n", label.c_str(), schemeLabel(run).c_str(),
                    devLabel.c_str(), s, lo, hi, updates / s);
        std::fflush(stdout);
      }
  };
  for (int n : solveSizes) solveAll("plant " + std::to_string(n) + "^3", makeLattice(n, "plant"));
  for (const auto& path : lattices) {
    const LoadedLattice loaded = loadDensityLattice(path, LightParams().woodThreshold);
    const Dims d = loaded.dense.dims;
    char label[512];
    std::snprintf(label, sizeof label, "%s %dx%dx%d (%.1f%% occupied)", path.substr(path.find_last_of('/') + 1).c_str(),
                  d.nx, d.ny, d.nz, 100.0 * double(occupiedNodes(loaded.dense)) / double(d.count()));
    solveAll(label, loaded.dense);
  }
  return 0;
} catch (const std::exception& e) {
  std::fprintf(stderr, "bench_lbsolve: %s\n", e.what());
  return 4;
}
