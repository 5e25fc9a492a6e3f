// parallel.h: the CPU side of the dispatch layer.
//
// parallelFor(n, f) calls f(i) for i in [0, n) on all cores (TBB). The same CANOPY_HD functor runs
// on the GPU through canopy::cuda::parallelFor (parallel_cuda.cuh), so the CPU path is the
// reference for every kernel.
#pragma once
#include <cstdint>

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

namespace canopy {

template <class F>
void parallelFor(int64_t n, F&& f, int64_t grain = 1024) {
  if (n <= 0) return;
  tbb::parallel_for(tbb::blocked_range<int64_t>(0, n, grain),
                    [&](const tbb::blocked_range<int64_t>& r) {
                      for (int64_t i = r.begin(); i != r.end(); ++i) f(i);
                    });
}

// Serial version with the same contract, for tests and deterministic reductions.
template <class F>
void serialFor(int64_t n, F&& f) {
  for (int64_t i = 0; i < n; ++i) f(i);
}

}  // namespace canopy
