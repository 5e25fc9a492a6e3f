// solver.cpp: the convergence loop shared by both backends, and the multi-GPU work queue.
#include "solver.h"

#include <atomic>
#include <chrono>
#include <exception>
#include <limits>
#include <mutex>
#include <thread>

#include "canopy/errors.h"

namespace canopy::lb {

const char* cudaSchemeName(CudaScheme scheme) {
  switch (scheme) {
    case CudaScheme::Shift: return "shift";
    case CudaScheme::Push: return "push";
    case CudaScheme::ShiftSplit: return "shift-split";
    case CudaScheme::PushFused: return "push-fused";
    case CudaScheme::Pull: return "pull";
    case CudaScheme::PullFused: return "pull-fused";
  }
  return "?";
}

SolveResult Solver::solve(const SolveSpec& spec) {
  const auto t0 = std::chrono::steady_clock::now();
  SolveResult r;
  r.residual = std::numeric_limits<float>::infinity();
  init(spec.boundary);
  const int cap = spec.maxIterations < 1 ? 1 : spec.maxIterations;
  const int every = spec.checkEvery < 1 ? 1 : spec.checkEvery;
  while (r.iterations < cap) {
    const int it = r.iterations + 1;
    const bool last = it == cap;
    const bool check = spec.tolerance > 0.f ? (it % every == 0 || last) : last;
    if (check) beforeCheckedStep();
    step(spec.omega);
    r.iterations = it;
    if (!check) continue;
    r.residual = residual();
    if (spec.tolerance > 0.f && r.residual <= spec.tolerance) break;
  }
  r.values = gather();
  r.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  return r;
}

std::vector<SolveResult> runSolves(const DenseLattice& lattice, const std::vector<SolveSpec>& specs,
                                   const Device& device,
                                   const std::function<void(size_t, const SolveResult&)>& onDone,
                                   CudaScheme scheme) {
  std::vector<SolveResult> results(specs.size());
  std::mutex doneMutex;
  auto finished = [&](size_t k) {
    if (!onDone) return;
    std::lock_guard<std::mutex> lock(doneMutex);
    onDone(k, results[k]);
  };
  if (!device.isCuda()) {
    auto solver = makeCpuSolver(lattice);
    for (size_t k = 0; k < specs.size(); ++k) {
      results[k] = solver->solve(specs[k]);
      finished(k);
    }
    return results;
  }
  std::vector<int> gpus;
  if (device.index >= 0) {
    gpus.push_back(device.index);
  } else {
    for (int g = 0; g < cudaDeviceCount(); ++g) gpus.push_back(g);
  }
  if (gpus.empty()) throw unsupported("--device cuda: no CUDA GPU is available");
  std::atomic<size_t> next{0};
  std::vector<std::exception_ptr> errors(gpus.size());
  std::vector<std::thread> threads;
  for (size_t t = 0; t < gpus.size(); ++t) {
    threads.emplace_back([&, t] {
      try {
        auto solver = makeCudaSolver(lattice, gpus[t], scheme);
        for (size_t k = next++; k < specs.size(); k = next++) {
          results[k] = solver->solve(specs[k]);
          finished(k);
        }
      } catch (...) {
        errors[t] = std::current_exception();
        next = specs.size();  // stop the other GPUs early
      }
    });
  }
  for (auto& th : threads) th.join();
  for (auto& e : errors)
    if (e) std::rethrow_exception(e);
  return results;
}

}  // namespace canopy::lb
