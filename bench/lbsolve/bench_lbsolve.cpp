// bench_lbsolve: throughput of the LB lighting update against the device's copy bandwidth, and the
// wall time of the 57 solves (19 bases x RGB) of one plant. Prints a Markdown table on stdout.
//
//   bench_lbsolve [--device cpu|cuda|cuda:N] [--sizes 128,256] [--solves-sizes 128]
//                 [--iterations 64]
//
// Throughput: one solve run for I/4 and for I iterations (tolerance 0); the difference divided by
// 3I/4 x nodes removes fixed costs (initialisation, gathering the result). Bytes per update are the
// nominal traffic of collide.h's push update: 19 floats read + 19 floats written + 4 bytes of
// coded density = 156 B. Copy bandwidth: a cudaMemcpy device-to-device of 1 GiB, counted as bytes
// read + bytes written, best of 10, measured in the same run (on the CPU: std::memcpy of 1 GiB with
// all threads, counted the same way). The 57-solve wall time uses the tool's defaults (tolerance
// 1e-4 checked every 16 iterations, cap 2 x the edge) on the chosen device: "cuda" = every GPU.
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstring>
#include <sstream>
#include <string>
#include <vector>

#ifdef CANOPY_HAS_CUDA
#include <cuda_runtime.h>
#endif

#include "canopy/device.h"
#include "canopy/parallel.h"
#include "fixtures.h"
#include "lattice_io.h"
#include "params.h"
#include "solver.h"

using namespace canopy;
using namespace canopy::lb;

namespace {
using Clock = std::chrono::steady_clock;
double since(Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); }

constexpr double kBytesPerUpdate = (2 * kQ + 1) * 4.0;

std::vector<int> parseList(const std::string& s) {
  std::vector<int> v;
  std::stringstream ss(s);
  for (std::string item; std::getline(ss, item, ',');) v.push_back(std::stoi(item));
  return v;
}

SolveSpec baseSpec(int b, int c, int iterations, float tolerance) {
  const LightParams p;
  SolveSpec s;
  s.omega = makeOmegaSet(p.sigmaA[c], p.sigmaS[c], p.g[c], p.gWood);
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

double solveSeconds(const DenseLattice& L, const Device& dev, int iterations) {
  const auto t0 = Clock::now();
  runSolves(L, {baseSpec(4, 1, iterations, 0.f)}, dev);
  return since(t0);
}
}  // namespace

int main(int argc, char** argv) {
  std::string deviceSpec = "auto";
  std::vector<int> sizes{128, 256}, solveSizes{128};
  int iterations = 64;
  for (int i = 1; i + 1 < argc; i += 2) {
    const std::string k = argv[i], v = argv[i + 1];
    if (k == "--device") deviceSpec = v;
    else if (k == "--sizes") sizes = parseList(v);
    else if (k == "--solves-sizes") solveSizes = parseList(v);
    else if (k == "--iterations") iterations = std::stoi(v);
    else {
      std::fprintf(stderr, "usage: bench_lbsolve [--device D] [--sizes 128,256] [--solves-sizes 128] [--iterations 64]\n");
      return 1;
    }
  }
  Device dev;
  try {
    dev = resolveDevice(deviceSpec);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "bench_lbsolve: %s\n", e.what());
    return 5;
  }
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
  std::printf("| lattice | nodes | node updates/s | bytes/update | GB/s | fraction of copy bandwidth |\n");
  std::printf("|---|---|---|---|---|---|\n");
  for (int n : sizes) {
    const fixtures::Plant plant = fixtures::makePlant(n);
    DenseLattice L = fixtures::denseOf(n, n, n, plant.density, plant.wood);
    L.stored = storedNodes(L.dims, plant.density);
    solveSeconds(L, one, 2);  // warm-up (allocation, first launch)
    const int i1 = std::max(1, iterations / 4), i2 = std::max(i1 + 1, iterations);
    const double t1 = solveSeconds(L, one, i1), t2 = solveSeconds(L, one, i2);
    const double rate = double(L.dims.count()) * (i2 - i1) / std::max(t2 - t1, 1e-9);
    std::printf("| %d^3 | %lld | %.3g | %.0f | %.1f | %.1f%% |\n", n, (long long)L.dims.count(), rate,
                kBytesPerUpdate, rate * kBytesPerUpdate / 1e9, 100.0 * rate * kBytesPerUpdate / bw);
    std::fflush(stdout);
  }
  std::printf("\n| lattice | device | 57 solves wall time | iterations (min..max) | node updates/s |\n");
  std::printf("|---|---|---|---|---|\n");
  for (int n : solveSizes) {
    const fixtures::Plant plant = fixtures::makePlant(n);
    DenseLattice L = fixtures::denseOf(n, n, n, plant.density, plant.wood);
    L.stored = storedNodes(L.dims, plant.density);
    std::vector<SolveSpec> specs;
    for (int b = 0; b < kQ; ++b)
      for (int c = 0; c < 3; ++c) specs.push_back(baseSpec(b, c, 2 * n, 1e-4f));
    std::vector<Device> devices{dev};
    if (dev.isCuda() && dev.index < 0 && cudaDeviceCount() > 1) devices.insert(devices.begin(), one);
    for (const Device& d : devices) {
      const auto t0 = Clock::now();
      const auto r = runSolves(L, specs, d);
      const double s = since(t0);
      int lo = 1 << 30, hi = 0;
      double updates = 0;
      for (const auto& x : r) {
        lo = std::min(lo, x.iterations);
        hi = std::max(hi, x.iterations);
        updates += double(x.iterations) * L.dims.count();
      }
      std::printf("| %d^3 | %s | %.3f s | %d..%d | %.3g |\n", n,
                  d.isCuda() && d.index < 0 ? ("cuda x" + std::to_string(cudaDeviceCount())).c_str() : d.str().c_str(),
                  s, lo, hi, updates / s);
      std::fflush(stdout);
    }
  }
  return 0;
}
