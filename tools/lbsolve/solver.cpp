// solver.cpp: the convergence loop shared by both backends, and the multi-GPU work queue.
#include "solver.h"

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstring>
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

SolveResult Solver::solve(const SolveSpec& spec) { return solveBatch({&spec})[0]; }

std::vector<SolveResult> Solver::solveBatch(const std::vector<const SolveSpec*>& specs) {
  if (specs.empty()) return {};
  if (int(specs.size()) > slots())
    throw runtimeError("internal: " + std::to_string(specs.size()) + " solves for a solver of " +
                       std::to_string(slots()) + " slots");
  const OmegaSet& omega = specs[0]->omega;
  for (const SolveSpec* s : specs)
    if (std::memcmp(&s->omega, &omega, sizeof omega) != 0)
      throw runtimeError("internal: the solves of one batch must share Omega");
  const auto t0 = std::chrono::steady_clock::now();
  std::vector<SolveResult> results(specs.size());
  std::vector<int> active;
  for (size_t k = 0; k < specs.size(); ++k) {
    results[k].residual = std::numeric_limits<float>::infinity();
    init(int(k), specs[k]->boundary);
    active.push_back(int(k));
  }
  std::vector<char> check(specs.size(), 0);
  while (!active.empty()) {
    for (int k : active) {
      const SolveSpec& spec = *specs[size_t(k)];
      const int it = results[size_t(k)].iterations + 1;
      const bool last = it == std::max(1, spec.maxIterations);
      check[size_t(k)] = spec.tolerance > 0.f ? (it % std::max(1, spec.checkEvery) == 0 || last) : last;
      if (check[size_t(k)]) beforeCheckedStep(k);
    }
    step(omega, active);
    std::vector<int> still;
    for (int k : active) {
      const SolveSpec& spec = *specs[size_t(k)];
      SolveResult& r = results[size_t(k)];
      ++r.iterations;
      bool done = r.iterations >= std::max(1, spec.maxIterations);
      if (check[size_t(k)]) {
        r.residual = residual(k);
        done = done || (spec.tolerance > 0.f && r.residual <= spec.tolerance);
      }
      if (!done) {
        still.push_back(k);
        continue;
      }
      r.values = gather(k);
      r.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    }
    active.swap(still);
  }
  return results;
}

std::vector<std::vector<size_t>> planBatches(const std::vector<SolveSpec>& specs, int perLaunch) {
  const size_t per = size_t(std::max(1, perLaunch));
  std::vector<std::vector<size_t>> groups;  // equal Omega, in order of first appearance
  for (size_t k = 0; k < specs.size(); ++k) {
    auto same = [&](const std::vector<size_t>& g) {
      return std::memcmp(&specs[g[0]].omega, &specs[k].omega, sizeof(OmegaSet)) == 0;
    };
    auto it = std::find_if(groups.begin(), groups.end(), same);
    if (it == groups.end()) {
      groups.push_back({k});
    } else {
      it->push_back(k);
    }
  }
  std::vector<std::vector<size_t>> batches;
  for (const auto& g : groups)
    for (size_t i = 0; i < g.size(); i += per)
      batches.emplace_back(g.begin() + std::ptrdiff_t(i), g.begin() + std::ptrdiff_t(std::min(g.size(), i + per)));
  return batches;
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
  if (specs.empty()) return results;
  std::vector<int> gpus;
  if (device.index >= 0) {
    gpus.push_back(device.index);
  } else {
    for (int g = 0; g < cudaDeviceCount(); ++g) gpus.push_back(g);
  }
  if (gpus.empty()) throw unsupported("--device cuda: no CUDA GPU is available");
  const size_t perGpu = size_t(std::max(1, run.solvesPerGpu));
  const std::vector<std::vector<size_t>> batches = planBatches(specs, run.solvesPerLaunch);
  const int slots = int(std::min(specs.size(), std::max_element(batches.begin(), batches.end(), [](auto& a, auto& b) {
                                                 return a.size() < b.size();
                                               })->size()));
  std::atomic<size_t> next{0};
  std::mutex errorMutex;
  std::exception_ptr error;
  auto guarded = [&](auto&& f) {
    try {
      f();
    } catch (...) {
      std::lock_guard<std::mutex> lock(errorMutex);
      if (!error) error = std::current_exception();
      next = batches.size();  // stop the other solvers early
    }
  };
  // A solver with fewer slots than a batch (memory) runs the batch in parts.
  auto work = [&](Solver& solver) {
    for (size_t b = next++; b < batches.size(); b = next++) {
      const auto& batch = batches[b];
      for (size_t i = 0; i < batch.size(); i += size_t(solver.slots())) {
        std::vector<const SolveSpec*> part;
        for (size_t j = i; j < std::min(batch.size(), i + size_t(solver.slots())); ++j) part.push_back(&specs[batch[j]]);
        std::vector<SolveResult> r = solver.solveBatch(part);
        for (size_t j = 0; j < part.size(); ++j) {
          results[batch[i + j]] = std::move(r[j]);
          finished(batch[i + j]);
        }
      }
    }
  };
  // Slots a solver on `gpu` gets: as many as a batch holds, fewer while they do not fit (with 1/8
  // of the need to spare), at least one.
  auto slotsThatFit = [&](int gpu) {
    int s = slots;
    const int64_t freeBytes = cudaFreeBytes(gpu);
    while (s > 1 && cudaSolverBytes(lattice, run.scheme, s) * 9 / 8 > freeBytes) --s;
    return s;
  };
  std::vector<std::thread> threads;
  for (int gpu : gpus) {
    threads.emplace_back([&, gpu] {
      guarded([&] {
        // The GPU's solvers are made one after another, so that each sees the memory the ones
        // before it took; a further solver is made only while another fits (with 1/8 to spare).
        std::vector<std::unique_ptr<Solver>> solvers;
        solvers.push_back(makeCudaSolver(lattice, gpu, run.scheme, slotsThatFit(gpu)));
        const int64_t need = cudaSolverBytes(lattice, run.scheme, solvers[0]->slots());
        while (solvers.size() < std::min(perGpu, batches.size()) && cudaFreeBytes(gpu) >= need + need / 8)
          solvers.push_back(makeCudaSolver(lattice, gpu, run.scheme, solvers[0]->slots()));
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
