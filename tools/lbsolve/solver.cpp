// solver.cpp: the convergence loop shared by both backends, and the multi-GPU work queue.
#include "solver.h"

#include <algorithm>
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
    case CudaScheme::Pull: return "pull";
  }
  return "?";
}

SolveResult Solver::solve(const SolveSpec& spec) {
  for (int kind = 0; kind < 2; ++kind)
    if (!omegaIsClassStructured(spec.omega.col[kind]))
      throw runtimeError("internal: an Omega whose rows are not constant over the direction classes "
                         "(collide.h, omegaIsClassStructured)");
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
                                   const CudaRun& run) {
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
  const size_t perGpu = size_t(std::max(1, run.solvesPerGpu));
  const int64_t need = cudaSolverBytes(lattice, run.scheme);
  std::atomic<size_t> next{0};
  std::mutex errorMutex;
  std::exception_ptr error;
  auto guarded = [&](auto&& f) {
    try {
      f();
    } catch (...) {
      std::lock_guard<std::mutex> lock(errorMutex);
      if (!error) error = std::current_exception();
      next = specs.size();  // stop the other solvers early
    }
  };
  auto work = [&](Solver& solver) {
    for (size_t k = next++; k < specs.size(); k = next++) {
      results[k] = solver.solve(specs[k]);
      finished(k);
    }
  };
  std::vector<std::thread> threads;
  for (int gpu : gpus) {
    threads.emplace_back([&, gpu] {
      guarded([&] {
        // The GPU's solvers are made one after another, so that each sees the memory the ones
        // before it took; a further solver is made only while another fits (with 1/8 to spare).
        std::vector<std::unique_ptr<Solver>> solvers;
        solvers.push_back(makeCudaSolver(lattice, gpu, run.scheme));
        while (solvers.size() < std::min(perGpu, specs.size()) && cudaFreeBytes(gpu) >= need + need / 8)
          solvers.push_back(makeCudaSolver(lattice, gpu, run.scheme));
        std::vector<std::thread> more;
        for (size_t s = 1; s < solvers.size(); ++s)
          more.emplace_back([&, s] { guarded([&] { work(*solvers[s]); }); });
        guarded([&] { work(*solvers[0]); });
        for (auto& t : more) t.join();
      });
    });
  }
  for (auto& th : threads) th.join();
  if (error) std::rethrow_exception(error);
  return results;
}

}  // namespace canopy::lb
