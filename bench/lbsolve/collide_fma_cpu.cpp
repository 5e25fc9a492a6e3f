// collide_fma_cpu.cpp: the CPU cost of one occupied node's LB collision (collide.h collideKind, 8
// lanes as solve_cpu.cpp runs it), unfused (the reference's IEEE operations) against fmaf (the
// pull-fused arithmetic). Not part of the build; run from the repository root:
//   g++ -std=c++17 -O2 -ffp-contract=off -I. -Icore/include bench/lbsolve/collide_fma_cpu.cpp -o /tmp/c && /tmp/c
//   g++ -std=c++17 -O2 -ffp-contract=off -mfma -I. -Icore/include bench/lbsolve/collide_fma_cpu.cpp -o /tmp/c && /tmp/c
// (docs/performance.md, 'Fused multiply-adds stay off': what making fmaf the reference on both sides would cost the CPU).
#include <chrono>
#include <cmath>
#include <cstdio>
#include <vector>
#include "tools/lbsolve/collide.h"
using namespace canopy::lb;
template <bool Fused>
double run(const OmegaSet& om, int reps, float& sink) {
  float f[kQ][8], out[kQ][8], rho[8];
  for (int l = 0; l < 8; ++l) rho[l] = 0.3f + 0.01f * l;
  auto t0 = std::chrono::steady_clock::now();
  for (int r = 0; r < reps; ++r) {
    for (int i = 0; i < kQ; ++i)
      for (int l = 0; l < 8; ++l) f[i][l] = 0.01f * float((i + l + r) & 15);
    collideKind<8, false, Fused>(om, rho, f, out);
    sink += out[r % kQ][r & 7];
  }
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count() / (double(reps) * 8) * 1e9;
}
int main() {
  OmegaSet om{};
  for (int k = 0; k < 2; ++k)
    for (int i = 0; i < kQ; ++i)
      for (int j = 0; j < kQ; ++j) om.col[k][i][j] = (i == j ? -0.5f : 0.02f) + 0.001f * float(k);
  float sink = 0;
  const int reps = 2000000;
  run<false>(om, reps / 10, sink);
  const double a = run<false>(om, reps, sink), b = run<true>(om, reps, sink);
  std::printf("ns per occupied node: unfused %.2f, fmaf %.2f (x%.2f)  [%g]\n", a, b, b / a, double(sink));
}
