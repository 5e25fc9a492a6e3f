// Physics of the LB lighting update on the CPU path (the reference): Omega's construction, one
// step's conservation and pass-through properties, diffusion (eq. 2.13-2.14), rotation symmetry of
// the 19 bases, and the convergence loop.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <vector>

#include "canopy/lattice_dirs.h"
#include "canopy/parallel.h"
#include "beam.h"
#include "collide.h"
#include "fixtures.h"
#include "pull_stream.h"
#include "shift_stream.h"
#include "params.h"
#include "solver.h"

using namespace canopy;
using namespace canopy::lb;
using lattice::dir;

namespace {

// A coded density per node: half the nodes empty, a fifth of the others wood (-rho), the rest leaf.
std::vector<float> randomCoded(int64_t n, uint64_t seed) {
  std::vector<float> coded(static_cast<size_t>(n));
  for (int64_t i = 0; i < n; ++i) {
    const float r = fixtures::hashUnit(uint64_t(i), seed);
    const float rho = r < 0.5f ? 0.f : (r - 0.5f) * 2.f;
    coded[size_t(i)] = fixtures::hashUnit(uint64_t(i), seed + 1) < 0.2f ? -rho : rho;
  }
  return coded;
}

// The push update's two state buffers, each in the initial state of a solve (initNode).
void initPush(const Dims& d, const float boundary[kQ], std::vector<float>& a, std::vector<float>& b) {
  a.assign(size_t(kQ) * size_t(d.count()), 0.f);
  b.assign(a.size(), 0.f);
  for (int z = 0; z < d.nz; ++z)
    for (int y = 0; y < d.ny; ++y)
      for (int x = 0; x < d.nx; ++x) {
        initNode(d, boundary, a.data(), x, y, z);
        initNode(d, boundary, b.data(), x, y, z);
      }
}

// One full step of the lattice with the shared per-node function (what both backends run).
void stepLattice(const OmegaSet& om, const Dims& d, const std::vector<float>& coded,
                 const std::vector<float>& in, std::vector<float>& out) {
  canopy::parallelFor(int64_t(d.ny) * d.nz, [&](int64_t row) {
    const int y = int(row % d.ny), z = int(row / d.ny);
    for (int x = 0; x < d.nx; ++x) updateNode(om, d, coded.data(), in.data(), out.data(), x, y, z);
  }, 4);
}

double sum(const std::vector<float>& v) {
  double s = 0;
  for (float x : v) s += x;
  return s;
}

// Random state: every f_m in [0, 1) at nodes >= `margin` from the lattice faces, 0 elsewhere;
// f_0 = 0 at leaf nodes when `leafF0Zero`.
std::vector<float> randomState(const Dims& d, int margin, uint64_t seed) {
  std::vector<float> s(size_t(kQ) * d.count(), 0.f);
  for (int z = margin; z < d.nz - margin; ++z)
    for (int y = margin; y < d.ny - margin; ++y)
      for (int x = margin; x < d.nx - margin; ++x)
        for (int m = 0; m < kQ; ++m) {
          const int64_t i = d.index(x, y, z);
          s[size_t(m * d.count() + i)] = fixtures::hashUnit(uint64_t(i * kQ + m), seed);
        }
  return s;
}

}  // namespace

TEST(Omega, ColumnsSumToZeroForAnyAnisotropy) {
  for (double g : {-1.0, -0.999999, -0.333, 0.0, 0.091, 0.5, 0.999999, 1.0})
    for (double sa : {0.0, 0.109, 0.5, 1.0}) {
      float col[kQ][kQ];
      buildOmega(sa, 1.0 - sa, g, col);
      for (int j = 0; j < kQ; ++j) {
        double s = 0;
        for (int i = 0; i < kQ; ++i) {
          ASSERT_TRUE(std::isfinite(col[j][i])) << g;
          s += col[j][i];
        }
        EXPECT_NEAR(s, 0.0, 1e-6) << "g " << g << " sigma_a " << sa << " column " << j;
      }
    }
}

TEST(Omega, MatchesEquations2_15To2_17ForIsotropicScattering) {
  const double sa = 0.2, ss = 0.8;
  float col[kQ][kQ];
  buildOmega(sa, ss, 0.0, col);  // g = 0: pn = 1 (isotropic)
  EXPECT_FLOAT_EQ(col[0][0], -1.f);
  for (int j = 1; j < kQ; ++j) EXPECT_FLOAT_EQ(col[j][0], float(sa));
  for (int i = 1; i < kQ; ++i) {
    const double w = lattice::isAxial(i) ? 1.0 / 12 : 1.0 / 24;
    EXPECT_FLOAT_EQ(col[0][i], float(w));
    for (int j = 1; j < kQ; ++j)
      EXPECT_NEAR(col[j][i], i == j ? -(sa + ss) + ss * w : ss * w, 1e-7) << i << "," << j;
  }
}

TEST(Omega, PhaseLimitsAtPlusMinusOneHaveNoZeroOverZero) {
  for (int j = 1; j < kQ; ++j)
    for (int i = 1; i < kQ; ++i) {
      const double plus = normalisedPhase(1.0, i, j), minus = normalisedPhase(-1.0, i, j);
      EXPECT_EQ(plus, i == j ? 24.0 / (lattice::isAxial(i) ? 2 : 1) : 0.0);
      EXPECT_EQ(minus, i == lattice::opposite(j) ? 24.0 / (lattice::isAxial(i) ? 2 : 1) : 0.0);
      // Continuity: g just inside (-1, 1) is close to the limit.
      EXPECT_NEAR(normalisedPhase(1.0 - 1e-6, i, j), plus, 1e-6 * 24);
      EXPECT_NEAR(normalisedPhase(-1.0 + 1e-6, i, j), minus, 1e-6 * 24);
    }
}

TEST(Omega, ForwardAndBackwardScatteringFollowG) {
  // g > 0 favours i = j, g < 0 favours the opposite direction (eq. 4.2).
  EXPECT_GT(normalisedPhase(0.5, 1, 1), normalisedPhase(0.5, 2, 1));
  EXPECT_LT(normalisedPhase(-0.5, 1, 1), normalisedPhase(-0.5, 2, 1));
  EXPECT_NEAR(normalisedPhase(0.0, 3, 7), 1.0, 1e-12);
}

// The grouped product (omega_product.h) relies on every row of Omega being constant over each
// class of directions (axial or diagonal c_j, and c_i . c_j): true of every matrix buildOmega
// makes, for any g including the limits; a single entry changed breaks it, and the solvers then
// refuse the matrix.
TEST(Omega, RowsAreConstantOverTheDirectionClasses) {
  for (double g : {-1.0, -0.999, -0.5, -0.12, 0.0, 0.3, 0.7, 0.999, 1.0})
    for (double sa : {0.0, 0.109, 0.5}) {
      const OmegaSet om = makeOmegaSet(sa, 0.891, g, -1.0, 0.0);
      EXPECT_TRUE(omegaIsClassStructured(om.col[0])) << g << " " << sa;
      EXPECT_TRUE(omegaIsClassStructured(om.col[1])) << g << " " << sa;
    }
  const OmegaSet good = makeOmegaSet(0.109, 0.891, 0.3, -1.0, 0.0);
  for (int i = 0; i < kQ; ++i)
    for (int j = 1; j < kQ; ++j) {
      OmegaSet bad = good;
      bad.col[0][j][i] = std::nextafter(bad.col[0][j][i], 2.f);
      // a class of one member (the diagonal entry, the opposite direction) stays constant
      int members = 0;
      for (int k = 1; k < kQ; ++k) {
        int dj = 0, dk = 0;
        for (int a = 0; a < 3; ++a) dj += dir(i, a) * dir(j, a), dk += dir(i, a) * dir(k, a);
        members += lattice::isAxial(k) == lattice::isAxial(j) && (i == 0 || dj == dk);
      }
      EXPECT_EQ(omegaIsClassStructured(bad.col[0]), members == 1) << i << " " << j;
      if (members > 1) {
        SolveSpec spec;
        spec.omega = bad;
        EXPECT_THROW(runSolves(fixtures::denseOf(4, 4, 4, std::vector<float>(64, 0.f), std::vector<float>(64, 0.f)),
                               {spec}, Device()),
                     std::exception);
      }
    }
}

// The grouped product equals the full matrix product up to rounding (its sums are taken in
// another order): within 1e-6 of the row's scale for leaf and wood matrices of many g, on random
// states; and each lane of the 8-lane form gives the 1-lane bits.
TEST(Omega, GroupedProductMatchesTheFullProduct) {
  for (double g : {-1.0, -0.5, 0.0, 0.3, 0.9, 1.0}) {
    const OmegaSet om = makeOmegaSet(0.109, 0.891, g, -1.0, 0.0);
    for (int kind = 0; kind < 2; ++kind)
      for (int t = 0; t < 50; ++t) {
        float f[kQ][8];
        for (int m = 0; m < kQ; ++m)
          for (int l = 0; l < 8; ++l) f[m][l] = fixtures::hashUnit(uint64_t((t * kQ + m) * 8 + l), 31);
        if (kind == 0)
          for (int l = 0; l < 8; ++l) f[0][l] = 0.f;  // leaf: f_0 zeroed before the product
        float acc[kQ][8];
        if (kind == 1) {
          omegaProduct<8, true, false>(om.col[1], f, acc);
        } else {
          omegaProduct<8, false, false>(om.col[0], f, acc);
        }
        for (int l = 0; l < 8; ++l) {
          float one[kQ][1], accOne[kQ][1];
          for (int m = 0; m < kQ; ++m) one[m][0] = f[m][l];
          if (kind == 1) {
            omegaProduct<1, true, false>(om.col[1], one, accOne);
          } else {
            omegaProduct<1, false, false>(om.col[0], one, accOne);
          }
          for (int i = 0; i < kQ; ++i) {
            double want = 0, scale = 0;
            for (int j = 0; j < kQ; ++j) {
              want += double(om.col[kind][j][i]) * double(f[j][l]);
              scale += std::abs(double(om.col[kind][j][i]) * double(f[j][l]));
            }
            ASSERT_NEAR(acc[i][l], want, 1e-6 * scale + 1e-30) << g << " kind " << kind << " row " << i;
            ASSERT_EQ(acc[i][l], accOne[i][0]) << "lane " << l << " row " << i;
          }
        }
      }
  }
}

TEST(Params, DefaultsAreTable6_1WithGFromFsAndBs) {
  LightParams p;
  EXPECT_NEAR(p.g[0], -0.120, 5e-4);
  EXPECT_NEAR(p.g[1], 0.091, 5e-4);
  EXPECT_NEAR(p.g[2], -0.333, 5e-4);
  for (int c = 0; c < 3; ++c) EXPECT_NEAR(p.sigmaA[c] + p.sigmaS[c], 1.0, 1e-12);
  EXPECT_EQ(p.gWood, -1.0);
  EXPECT_EQ(p.woodThreshold, 0.5);
}

TEST(Params, FileOverridesAndRejectsNonsense) {
  LightParams p;
  applyParams(p, nlohmann::json::parse(R"({"sigma_a": 0.2, "g": [0.1, 0.2, 0.3], "wood_threshold": 0.25})"), "t");
  EXPECT_EQ(p.sigmaA[1], 0.2);
  EXPECT_NEAR(p.sigmaS[1], 0.8, 1e-12);
  EXPECT_EQ(p.g[2], 0.3);
  EXPECT_EQ(p.woodThreshold, 0.25);
  auto bad = [](const char* text) {
    LightParams q;
    try {
      applyParams(q, nlohmann::json::parse(text), "p.json");
    } catch (const Error& e) {
      EXPECT_EQ(e.code(), ExitCode::InvalidInput) << text;
      EXPECT_NE(std::string(e.what()).find("p.json"), std::string::npos);
      return true;
    }
    return false;
  };
  EXPECT_TRUE(bad(R"({"sigma_b": 1})"));
  EXPECT_TRUE(bad(R"({"g": 1.5})"));
  EXPECT_TRUE(bad(R"({"g": 0.1, "fs": 0.2})"));
  EXPECT_TRUE(bad(R"({"sigma_a": [0.1, 0.2]})"));
  EXPECT_TRUE(bad(R"({"sigma_a": -0.1})"));
  EXPECT_TRUE(bad(R"({"fs": 0, "bs": 0})"));
  EXPECT_TRUE(bad(R"([1, 2])"));
}

// Column sums of zero: one collision conserves sum_m f_m exactly up to float rounding (the
// relative tolerance 2e-6 is ~20 ulp for sums of 19 terms), at leaf nodes with sigma_a = 0 (f_0
// already 0) and at wood nodes for any sigma_a (absorbed light is kept in f_0 there).
TEST(Collide, OneNodeConservesEnergyWithoutAbsorption) {
  for (double sigma : {0.0, 4.0}) {  // linear and Beer-Lambert interaction: any p conserves
  const OmegaSet leaf = makeOmegaSet(0.0, 1.0, 0.091, -1.0, sigma);
  const OmegaSet absorbing = makeOmegaSet(0.3, 0.7, -0.333, -1.0, sigma);
  for (int t = 0; t < 500; ++t) {
    float f[kQ], out[kQ];
    for (int m = 0; m < kQ; ++m) f[m] = fixtures::hashUnit(uint64_t(t * kQ + m), 3);
    const float rho = 0.05f + 0.95f * fixtures::hashUnit(uint64_t(t), 4);
    const bool wood = t % 2;
    if (!wood) f[0] = 0.f;
    double before = 0, after = 0;
    for (int m = 0; m < kQ; ++m) before += f[m];
    collide(wood ? absorbing : leaf, wood ? -rho : rho, f, out);
    for (int m = 0; m < kQ; ++m) after += out[m];
    EXPECT_NEAR(after, before, 2e-6 * before) << t;
  }
  }
}

// The same on a lattice: energy placed >= 2 nodes inside, sigma_a = 0, random densities with wood
// and leaf nodes: after one step (collide + stream) the total over the lattice is unchanged.
TEST(Collide, OneLatticeStepConservesEnergyInTheInterior) {
  const Dims d{12, 10, 11};
  std::vector<float> coded(size_t(d.count()));
  for (int64_t i = 0; i < d.count(); ++i) {
    const float r = fixtures::hashUnit(uint64_t(i), 11);
    coded[size_t(i)] = r < 0.3f ? 0.f : (r < 0.4f ? -r : r);  // empty, wood, leaf
  }
  std::vector<float> in = randomState(d, 2, 5), out(in.size(), 0.f);
  for (int64_t i = 0; i < d.count(); ++i)
    if (coded[size_t(i)] >= 0.f) in[size_t(i)] = 0.f;  // f_0 = 0 at leaf nodes (zeroed each step)
  for (double sigma : {0.0, 4.0}) {
    const OmegaSet om = makeOmegaSet(0.0, 1.0, -0.12, -1.0, sigma);
    stepLattice(om, d, coded, in, out);
    EXPECT_NEAR(sum(out), sum(in), 2e-6 * sum(in)) << sigma;
  }
}

// Zero density: a pure pass-through, f_m(r + c_m) = f_m(r) bit for bit (f_0 is zeroed, as in
// listing 5.1, and only ever holds absorbed light).
TEST(Collide, ZeroDensityIsAPurePassThrough) {
  const Dims d{9, 8, 7};
  const std::vector<float> coded(size_t(d.count()), 0.f);
  const std::vector<float> in = randomState(d, 0, 9);
  std::vector<float> out(in.size(), -1.f);
  stepLattice(makeOmegaSet(0.109, 0.891, -0.12, -1.0, 0.0), d, coded, in, out);
  const int64_t n = d.count();
  for (int z = 0; z < d.nz; ++z)
    for (int y = 0; y < d.ny; ++y)
      for (int x = 0; x < d.nx; ++x)
        for (int m = 1; m < kQ; ++m) {
          const int tx = x + dir(m, 0), ty = y + dir(m, 1), tz = z + dir(m, 2);
          if (!d.interior(tx, ty, tz)) continue;
          ASSERT_EQ(out[size_t(m * n + d.index(tx, ty, tz))], in[size_t(m * n + d.index(x, y, z))]);
        }
}

// §2.2: sigma_a = 0 and g = 1 is identical to a pass-through, at full density.
TEST(Collide, ForwardScatteringWithoutAbsorptionIsAPassThrough) {
  const OmegaSet om = makeOmegaSet(0.0, 1.0, 1.0, -1.0, 0.0);
  for (int t = 0; t < 200; ++t) {
    float f[kQ], out[kQ];
    for (int m = 0; m < kQ; ++m) f[m] = fixtures::hashUnit(uint64_t(t * kQ + m), 21);
    const float rho = t == 0 ? 1.f : fixtures::hashUnit(uint64_t(t), 22);
    collide(om, rho, f, out);
    EXPECT_EQ(out[0], 0.f);
    for (int m = 1; m < kQ; ++m) EXPECT_EQ(out[m], f[m]) << t << " " << m;
  }
}

// Eq. 2.13-2.14: with lattice spacing and time step 1, the total density spreads diffusively with
// D = [(2/sigma_t) - 1] / [4 (1 + sigma_a)], where the node density scales sigma (sigma_t ->
// rho sigma_t). A pulse in a homogeneous medium (sigma_a = 0, g = 0) must widen along x at
// Var(t2) - Var(t1) = 2 D (t2 - t1). At rho = 1 each step is an exact random walk (E[dx^2] = 1/2,
// D = 1/4); at rho = 0.5 it is a persistent walk (D = 3/4). Tolerance 1% (measured: 0.2%): the lattice is finite
// (< 1e-4 of the mass reaches the boundary) and t1 = 10 leaves a small transient.
TEST(Diffusion, HomogeneousMediumSpreadsWithTheCoefficientOfEq2_14) {
  for (float rho : {1.0f, 0.5f}) {
    const int n = rho == 1.f ? 41 : 61, t1 = 10, t2 = rho == 1.f ? 50 : 40;
    const Dims d{n, n, n};
    const std::vector<float> coded(size_t(d.count()), rho);
    std::vector<float> a(size_t(kQ) * d.count(), 0.f), b(a.size(), 0.f);
    const int c = n / 2;
    for (int m = 1; m < kQ; ++m) a[size_t(m * d.count() + d.index(c, c, c))] = lattice::weight(m);
    const OmegaSet om = makeOmegaSet(0.0, 1.0, 0.0, -1.0, 0.0);
    auto varianceX = [&](const std::vector<float>& s) {
      double m0 = 0, m1 = 0, m2 = 0;
      for (int z = 0; z < n; ++z)
        for (int y = 0; y < n; ++y)
          for (int x = 0; x < n; ++x) {
            const double r = nodeTotal(s.data(), d.count(), d.index(x, y, z));
            m0 += r, m1 += r * x, m2 += r * x * x;
          }
      return m2 / m0 - (m1 / m0) * (m1 / m0);
    };
    double v1 = 0;
    for (int t = 1; t <= t2; ++t) {
      stepLattice(om, d, coded, a, b);
      std::swap(a, b);
      if (t == t1) v1 = varianceX(a);
    }
    const double measured = (varianceX(a) - v1) / (2.0 * (t2 - t1));
    const double sigmaT = rho * 1.0, sigmaA = 0.0;
    const double expected = ((2.0 / sigmaT) - 1.0) / (4.0 * (1.0 + sigmaA));
    EXPECT_NEAR(measured, expected, 0.01 * expected) << "rho " << rho;
    std::printf("diffusion rho %.2f: D measured %.5f, eq. 2.14 %.5f\n", rho, measured, expected);
  }
}

namespace {
std::vector<SolveResult> solveAllBases(const DenseLattice& L, int iterations, int channel = 1) {
  const LightParams p;
  std::vector<SolveSpec> specs;
  for (int b = 0; b < kQ; ++b) {
    SolveSpec s;
    s.omega = makeOmegaSet(p.sigmaA[channel], p.sigmaS[channel], p.g[channel], -1.0, 0.0);
    for (int m = 0; m < kQ; ++m) s.boundary[m] = (b == 0 || m == b) ? 1.f : 0.f;
    s.maxIterations = iterations;
    s.tolerance = 0.f;
    specs.push_back(s);
  }
  return runSolves(L, specs, Device());
}
}  // namespace

// Rotating the lattice by 90 degrees about an axis permutes the 18 directional bases:
// B'_{sigma(j)}(R r) = B_j(r) with c_{sigma(j)} = R c_j; B_0 is invariant. Omega is invariant
// under the permutation, so only the summation order differs: tolerance 1e-5 of the base's max.
TEST(Symmetry, Rotating90DegreesPermutesTheBases) {
  const int n = 14;
  const fixtures::Plant plant = fixtures::makePlant(n, 17);
  // Make it asymmetric so the test is not vacuous: clear one octant of the crown.
  std::vector<float> density = plant.density, wood = plant.wood;
  for (int z = 0; z < n / 2; ++z)
    for (int y = n / 2; y < n; ++y)
      for (int x = 0; x < n / 2; ++x) density[(size_t(z) * n + y) * n + x] = 0.f;
  for (int axis = 0; axis < 3; ++axis) {
    // R: 90 degrees about `axis`: (a, b) -> (-b, a) in the plane of the other two axes.
    const int p = (axis + 1) % 3, q = (axis + 2) % 3;
    auto rotVec = [&](const int v[3], int out[3]) {
      out[axis] = v[axis];
      out[p] = -v[q];
      out[q] = v[p];
    };
    auto rotNode = [&](const int v[3], int out[3]) {  // about the lattice centre
      out[axis] = v[axis];
      out[p] = (n - 1) - v[q];
      out[q] = v[p];
    };
    std::vector<float> rd(density.size()), rw(wood.size());
    for (int z = 0; z < n; ++z)
      for (int y = 0; y < n; ++y)
        for (int x = 0; x < n; ++x) {
          const int v[3] = {x, y, z};
          int r[3];
          rotNode(v, r);
          const size_t from = (size_t(z) * n + y) * n + x, to = (size_t(r[2]) * n + r[1]) * n + r[0];
          rd[to] = density[from];
          rw[to] = wood[from];
        }
    const auto base = solveAllBases(fixtures::denseOf(n, n, n, density, wood), 24);
    const auto rotated = solveAllBases(fixtures::denseOf(n, n, n, rd, rw), 24);
    for (int j = 0; j < kQ; ++j) {
      const int c[3] = {dir(j, 0), dir(j, 1), dir(j, 2)};
      int rc[3];
      rotVec(c, rc);
      const int sj = lattice::indexOf(rc[0], rc[1], rc[2]);
      ASSERT_GE(sj, 0);
      if (j == 0) {
        EXPECT_EQ(sj, 0);
      }
      const float maxv = *std::max_element(base[j].values.begin(), base[j].values.end());
      double worst = 0;
      for (int z = 0; z < n; ++z)
        for (int y = 0; y < n; ++y)
          for (int x = 0; x < n; ++x) {
            const int v[3] = {x, y, z};
            int r[3];
            rotNode(v, r);
            const float a = base[j].values[(size_t(z) * n + y) * n + x];
            const float b = rotated[sj].values[(size_t(r[2]) * n + r[1]) * n + r[0]];
            worst = std::max(worst, double(std::abs(a - b)));
          }
      EXPECT_LE(worst, 1e-5 * maxv) << "axis " << axis << " base " << j << " -> " << sj;
    }
    // Not vacuous: the rotated solve of B_j differs from the unrotated B_j somewhere (j = 1).
    EXPECT_NE(base[1].values, rotated[1].values);
  }
}

// An empty lattice is pure streaming: B_j = 1 at every interior node (sum of one f_j = 1),
// B_0 = 18 (f_0 never leaves the boundary), boundary nodes keep their totals (1 or 19). The
// solve converges (residual 0) once the light has crossed the lattice, well before the cap.
TEST(Solver, EmptyLatticeConvergesToTheBoundaryValues) {
  const int n = 12;
  const std::vector<float> zero(size_t(n) * n * n, 0.f);
  const DenseLattice L = fixtures::denseOf(n, n, n, zero, zero);
  const LightParams p;
  for (int b : {0, 1, 8, 18}) {
    SolveSpec s;
    s.omega = makeOmegaSet(p.sigmaA[0], p.sigmaS[0], p.g[0], -1.0, 0.0);
    for (int m = 0; m < kQ; ++m) s.boundary[m] = (b == 0 || m == b) ? 1.f : 0.f;
    s.maxIterations = 4 * n;
    s.tolerance = 1e-6f;
    s.checkEvery = 4;
    const SolveResult r = runSolves(L, {s}, Device())[0];
    EXPECT_LT(r.iterations, 4 * n);
    EXPECT_EQ(r.residual, 0.f);
    for (int z = 0; z < n; ++z)
      for (int y = 0; y < n; ++y)
        for (int x = 0; x < n; ++x) {
          const bool interior = L.dims.interior(x, y, z);
          const float want = b == 0 ? (interior ? 18.f : 19.f) : 1.f;
          ASSERT_EQ(r.values[size_t(L.dims.index(x, y, z))], want) << b << " " << x << y << z;
        }
  }
}

TEST(Solver, ToleranceZeroRunsExactlyNIterations) {
  const fixtures::Plant plant = fixtures::makePlant(10);
  const DenseLattice L = fixtures::denseOf(10, 10, 10, plant.density, plant.wood);
  SolveSpec s;
  s.omega = makeOmegaSet(0.1, 0.9, 0.0, -1.0, 0.0);
  s.boundary[4] = 1.f;
  s.maxIterations = 7;
  s.tolerance = 0.f;
  const SolveResult r = runSolves(L, {s}, Device())[0];
  EXPECT_EQ(r.iterations, 7);
  EXPECT_GT(r.residual, 0.f);  // not converged after 7 steps on a 10^3 lattice
}

// Light entering a plant from above is absorbed and scattered: below the crown it is darker than
// above it. Values never go negative.
TEST(Solver, APlantCastsIndirectShadow) {
  const int n = 20;
  const fixtures::Plant plant = fixtures::makePlant(n);
  const DenseLattice L = fixtures::denseOf(n, n, n, plant.density, plant.wood);
  const auto r = solveAllBases(L, 2 * n, 1);
  const auto& down = r[4];  // light travelling -y: the sun overhead
  double top = 0, bottom = 0;
  for (int z = 1; z < n - 1; ++z)
    for (int x = 1; x < n - 1; ++x) {
      top += down.values[size_t(L.dims.index(x, n - 3, z))];
      bottom += down.values[size_t(L.dims.index(x, 2, z))];
    }
  EXPECT_LT(bottom, top);
  for (const auto& s : r)
    for (float v : s.values) ASSERT_GE(v, 0.f);
}

// The push update restricted to the beam of base b (beam.h's definition): only f_0 and f_b are
// ever non-zero; a node keeps max(0, f_b - sigma_t p_b f_b) of the beam (what does not interact
// there) and absorbs max(0, f_0 + Omega_00 p_0 f_0 + Omega_0b p_b f_b) of it into f_0 (zeroed first
// at leaf nodes), p_m the node's interaction probabilities (collide.h). Node by node, iteration by
// iteration, from the initial state of initNode (interior 0, boundary f_b = 1); returns f_0 + f_b
// at every node.
std::vector<float> beamByIteration(const DenseLattice& L, const OmegaSet& om, int b, int iterations) {
  const Dims d = L.dims;
  const int64_t n = d.count();
  const int cls = lattice::isAxial(b) ? 0 : 1;
  std::vector<float> f0(size_t(n), 0.f), fb(size_t(n), 0.f);
  for (int z = 0; z < d.nz; ++z)
    for (int y = 0; y < d.ny; ++y)
      for (int x = 0; x < d.nx; ++x)
        if (!d.interior(x, y, z)) fb[size_t(d.index(x, y, z))] = 1.f;
  for (int t = 0; t < iterations; ++t) {
    std::vector<float> g0 = f0, gb = fb;  // boundary nodes keep their values
    for (int z = 0; z < d.nz; ++z)
      for (int y = 0; y < d.ny; ++y)
        for (int x = 0; x < d.nx; ++x) {
          const int64_t p = d.index(x, y, z);
          const float coded = L.coded[size_t(p)];
          const bool wood = coded < 0.f;
          const float rho[1] = {wood ? -coded : coded};
          const int k = wood ? 1 : 0;
          float a0 = wood ? f0[size_t(p)] : 0.f, ab = fb[size_t(p)];
          if (rho[0] != 0.f) {
            float pr[2][1];
            interactionProbabilities<1>(om, rho, pr);
            float acc0 = 0.f;
            acc0 += om.col[k][0][0] * (pr[0][0] * a0);
            acc0 += om.col[k][b][0] * (pr[cls][0] * ab);
            const float x0 = a0 + acc0, xb = ab + -om.sigmaT * (pr[cls][0] * ab);
            a0 = x0 > 0.f ? x0 : 0.f;
            ab = xb > 0.f ? xb : 0.f;
          }
          if (d.interior(x, y, z)) g0[size_t(p)] = a0;
          const int tx = x + dir(b, 0), ty = y + dir(b, 1), tz = z + dir(b, 2);
          if (d.interior(tx, ty, tz)) gb[size_t(d.index(tx, ty, tz))] = ab;
        }
    f0.swap(g0);
    fb.swap(gb);
  }
  std::vector<float> total(static_cast<size_t>(n));
  for (int64_t p = 0; p < n; ++p) total[size_t(p)] = f0[size_t(p)] + fb[size_t(p)];
  return total;
}

// The direct beam of a sun base (beam.h): directBeam's walk along the beam gives, bit for bit, what
// the iterated update restricted to the beam gives, for leaf and wood nodes, densities that clamp,
// axial and diagonal bases, all three channels, before and after the beam crosses the lattice, with
// the Beer-Lambert interaction (the default, sigma 4) and the dissertation's linear one.
TEST(DirectBeam, EqualsTheUpdateRestrictedToTheBeam) {
  const int nx = 19, ny = 22, nz = 17;  // not a cube: every axis's depth counts
  std::vector<float> density(size_t(nx) * ny * nz, 0.f), wood(density.size(), 0.f);
  for (size_t i = 0; i < density.size(); ++i) {
    const float r = fixtures::hashUnit(i, 11);
    density[i] = r < 0.4f ? 0.f : 2.5f * (r - 0.4f);  // up to 1.5: some nodes clamp at 0 (linear)
    wood[i] = fixtures::hashUnit(i, 12) < 0.2f ? 1.f : 0.f;
  }
  const DenseLattice L = fixtures::denseOf(nx, ny, nz, density, wood);
  const LightParams p;
  for (double sigma : {0.0, 0.3, 4.0})
    for (int c = 0; c < 3; ++c) {
      const OmegaSet full = makeOmegaSet(p.sigmaA[c], p.sigmaS[c], p.g[c], p.gWood, sigma);
      for (int b : {1, 4, 6, 7, 12, 18}) {
        ASSERT_GT(full.col[0][b][0], 0.f);  // sigma_a: the beam is absorbed into f_0
        for (int iterations : {3, 9, 40}) {
          const std::vector<float> want = beamByIteration(L, full, b, iterations);
          const std::vector<float> got = directBeam(L, full, b, iterations);
          ASSERT_EQ(got.size(), L.stored.size());
          int64_t lit = 0;
          for (size_t i = 0; i < got.size(); ++i) {
            ASSERT_EQ(got[i], want[size_t(L.stored[i])]) << "sigma " << sigma << " base " << b << " channel " << c
                                                         << " iterations " << iterations << " node " << L.stored[i];
            lit += got[i] > 0.f;
          }
          EXPECT_GT(lit, int64_t(got.size() / 8)) << b;  // the beam reached some of the interior
        }
      }
    }
}

// On a node holding only beam light (f_b), the full collision's row 0 is the beam's absorption bit
// for bit (the grouped product, omega_product.h, adds exact zeros for every other class of the
// row), and its row b keeps the beam's unscattered part plus what the interaction scatters back
// into c_b itself (Omega_bb + sigma_t = sigma_s pn_bb / 12 or / 24 of it): scattered light, which
// beam.h leaves in S_b.
TEST(DirectBeam, TheFullCollisionOfABeamOnlyStateKeepsTheBeamAndItsForwardScatter) {
  const LightParams p;
  for (double sigma : {0.0, 4.0})
    for (int c = 0; c < 3; ++c) {
      const OmegaSet om = makeOmegaSet(p.sigmaA[c], p.sigmaS[c], p.g[c], p.gWood, sigma);
      for (int b = 1; b < kQ; ++b)
        for (float rho : {0.05f, 0.3f, 1.f})
          for (float coded : {rho, -rho}) {
            float f[kQ] = {}, out[kQ];
            f[b] = 0.7f;
            const int k = coded < 0.f ? 1 : 0;
            const float a0 = f[0], ab = f[b];
            const float r[1] = {rho};
            float pr[2][1];
            interactionProbabilities<1>(om, r, pr);
            const float pb = pr[lattice::isAxial(b) ? 0 : 1][0];
            collide(om, coded, f, out);
            const float kept = ab + -om.sigmaT * (pb * ab);       // the beam (beam.h)
            const float forward = (om.col[k][b][b] + om.sigmaT) * (pb * ab);  // scattered back into c_b
            EXPECT_GE(out[b], kept) << sigma << " " << c << " " << b << " " << coded;
            EXPECT_NEAR(out[b], kept + forward, 1e-6f) << sigma << " " << c << " " << b << " " << coded;
            if (k == 1) {
              EXPECT_EQ(forward, 0.f);  // wood (g = -1) scatters nothing forward
            }
            float acc0 = 0.f;
            acc0 += om.col[k][0][0] * (pr[0][0] * a0);
            acc0 += om.col[k][b][0] * (pb * ab);
            const float x0 = a0 + acc0;
            EXPECT_EQ(out[0], x0 > 0.f ? x0 : 0.f) << c << " " << b << " " << coded;
          }
    }
}

// The Beer-Lambert interaction (the default): through a uniform run of nodes the beam of an axial
// base falls as exp(-sigma rho n) and that of a diagonal base as exp(-sigma rho n sqrt 2), n nodes
// crossed (sqrt 2 cells each along a diagonal): the transmittance of the player's medium
// (canopy-play --sigma) along the same path. The linear collision (the dissertation's) keeps
// (1 - rho)^n instead, far from it at the densities of a leaf crown.
TEST(DirectBeam, BeerLambertBeamFollowsThePlayersTransmittance) {
  const int n = 24;
  const float rho = 0.1f;
  std::vector<float> density(size_t(n) * n * n, 0.f), wood(density.size(), 0.f);
  for (int z = 1; z < n - 1; ++z)
    for (int y = 1; y < n - 1; ++y)
      for (int x = 1; x < n - 1; ++x) density[size_t((z * n + y) * n + x)] = rho;
  const DenseLattice L = fixtures::denseOf(n, n, n, density, wood);
  const double sigma = 4.0;
  const OmegaSet om = makeOmegaSet(0.109, 0.891, -0.12, -1.0, sigma);
  ASSERT_FLOAT_EQ(om.sigmaT, 1.f);
  for (int b : {4, 9}) {  // (0,-1,0) and (+1,-1,0)
    const std::vector<float> beam = directBeam(L, om, b, 2 * n);
    // node (x, y, z) with y = n - 1 - k lies k steps below the top boundary along c_b (both bases
    // move -1 in y per step; x = n - 2 is farther from the x = 0 side, where base 9 also enters);
    // f_b there has crossed k - 1 nodes; the total adds f_0 (what the node absorbs of it).
    const int x = n - 2, z = n / 2;
    for (int k = 2; k < n - 3; ++k) {
      const int y = n - 1 - k;
      const double crossed = k - 1;
      const double length = crossed * (lattice::isAxial(b) ? 1.0 : std::sqrt(2.0));
      const double fb = std::exp(-sigma * rho * length);
      const double pInteract = 1.0 - std::exp(-sigma * rho * (lattice::isAxial(b) ? 1.0 : std::sqrt(2.0)));
      const double want = fb * (1.0 + 0.109 * pInteract);  // f_b + f_0 = f_b + sigma_a p f_b (leaf)
      size_t idx = 0;
      const int64_t node = L.dims.index(x, y, z);
      while (L.stored[idx] != node) ++idx;
      EXPECT_NEAR(beam[idx], want, 2e-6 + 2e-5 * want) << "base " << b << " depth " << k;
    }
  }
}

// lbExpNeg (collide.h), the exp(-x) every node's interaction is computed with on CPU and GPU alike:
// within 2e-7 relative of exp(-x) over the range densities and sigma give, exactly 1 at 0,
// monotone, and 0 far out.
TEST(Collide, PortableExpNegIsAccurateAndMonotone) {
  EXPECT_EQ(lbExpNeg(0.f), 1.f);
  float prev = 2.f;
  double worst = 0;
  for (int i = 0; i <= 200000; ++i) {
    const float x = float(i) * 4e-4f;  // 0 .. 80
    const float e = lbExpNeg(x);
    const double want = std::exp(-double(x));
    worst = std::max(worst, std::abs(e - want) / want);
    ASSERT_LE(e, prev) << x;
    prev = e;
  }
  EXPECT_LT(worst, 2e-7);
  EXPECT_EQ(lbExpNeg(90.f), 0.f);
  EXPECT_EQ(lbExpNeg(std::numeric_limits<float>::infinity()), 0.f);
}

// What remains of a sun base without its beam is the scattered light: none in a lattice without
// matter (the beam passes whole), never negative beyond rounding, and present in and around a plant.
TEST(DirectBeam, TheScatteredRemainderIsZeroWithoutMatterAndNeverNegative) {
  const int n = 20;
  const LightParams p;
  const std::vector<float> zero(size_t(n) * n * n, 0.f);
  const fixtures::Plant plant = fixtures::makePlant(n);
  for (bool empty : {true, false}) {
    const DenseLattice L = empty ? fixtures::denseOf(n, n, n, zero, zero)
                                 : fixtures::denseOf(n, n, n, plant.density, plant.wood);
    for (int b : {4, 9, 15}) {
      SolveSpec s;
      s.omega = makeOmegaSet(p.sigmaA[1], p.sigmaS[1], p.g[1], p.gWood, p.sigma);  // the tool's default
      s.boundary[b] = 1.f;
      s.maxIterations = 2 * n;
      const SolveResult total = runSolves(L, {s}, Device())[0];
      const std::vector<float> beam = directBeam(L, s.omega, b, total.iterations);
      double scattered = 0, beamSum = 0;
      for (size_t i = 0; i < beam.size(); ++i) {
        const float d = total.values[i] - beam[i];
        if (empty) {
          ASSERT_EQ(d, 0.f) << i;
        }
        ASSERT_GE(d, -1e-6f) << "base " << b << " node " << i;
        scattered += d;
        beamSum += beam[i];
      }
      if (!empty) {
        EXPECT_GT(scattered, 0.01 * beamSum) << b;  // the crown scatters a visible share
        EXPECT_LT(scattered, beamSum) << b;
      }
    }
  }
}

// The CPU solver updates runs of 8 same-kind nodes with updateLanes<8>; the GPU runs
// updateNode (= updateLanes<1>) per thread. Both must give the same bits, node by node, on a
// lattice mixing empty, leaf and wood nodes, after several steps.
TEST(Collide, EightLaneAndOneLaneUpdatesAreBitIdentical) {
  const int n = 21;  // not a multiple of 8: exercises the per-node tail too
  const fixtures::Plant plant = fixtures::makePlant(n, 5);
  const DenseLattice L = fixtures::denseOf(n, n, n, plant.density, plant.wood);
  SolveSpec s;
  s.omega = makeOmegaSet(0.109, 0.891, -0.12, -1.0, 4.0);  // Beer-Lambert: lbExpNeg in 8 lanes and in 1
  s.boundary[0] = 1.f, s.boundary[3] = 0.5f, s.boundary[9] = 0.25f;
  s.maxIterations = 9;
  const SolveResult solver = runSolves(L, {s}, Device())[0];  // 8-lane path where possible

  std::vector<float> a, b;
  initPush(L.dims, s.boundary, a, b);
  for (int t = 0; t < 9; ++t) {
    stepLattice(s.omega, L.dims, L.coded, a, b);  // updateNode only
    std::swap(a, b);
  }
  for (int64_t i = 0; i < L.dims.count(); ++i)
    ASSERT_EQ(solver.values[size_t(i)], nodeTotal(a.data(), L.dims.count(), i)) << i;
}

// The CUDA "pull" scheme (pull_stream.h): aligned stores of each node's post-collision values in
// tiles of 32 nodes, arrivals read from the neighbours. Run here with the same CANOPY_HD functions
// the kernels call, on an odd-sized box (x padded from 37 to 64: two tiles per row) whose boundary
// layer is occupied too (leaf and wood): after every iteration the arrivals it would read, and
// their totals, are the push update's state bit for bit.
TEST(PullStreaming, MatchesThePushUpdateBitForBitAtEveryIteration) {
  const Dims d{37, 9, 11};
  const int64_t n = d.count();
  const std::vector<float> coded = randomCoded(n, 5);
  const OmegaSet om = makeOmegaSet(0.109, 0.891, -0.3, -1.0, 4.0);
  float boundary[kQ];
  for (int m = 0; m < kQ; ++m) boundary[m] = 0.04f * float(m + 2);
  std::vector<float> a, b;  // the push update's state (reference)
  initPush(d, boundary, a, b);
  const PullLayout L = pullLayout(d);
  ASSERT_EQ(L.nxp, 64);
  const float nan = std::numeric_limits<float>::quiet_NaN();  // padding and unwritten slots: never read
  std::vector<float> in(size_t(pullStateFloats(L)), nan), out(in.size(), nan);
  for (int z = 0; z < d.nz; ++z)
    for (int y = 0; y < d.ny; ++y)
      for (int x = 0; x < d.nx; ++x) {
        if (d.interior(x, y, z)) {
          for (int m = 0; m < kQ; ++m) in[size_t(pullSlot(L, m, x, y, z))] = out[size_t(pullSlot(L, m, x, y, z))] = 0.f;
        } else {
          pullBoundaryNode(om, L, boundary, coded[size_t(d.index(x, y, z))], in.data(), x, y, z);
          pullBoundaryNode(om, L, boundary, coded[size_t(d.index(x, y, z))], out.data(), x, y, z);
        }
      }
  for (int t = 0; t < 30; ++t) {
    stepLattice(om, d, coded, a, b);
    std::swap(a, b);
    for (int z = 0; z < d.nz; ++z)
      for (int y = 0; y < d.ny; ++y)
        for (int x = 0; x < L.nxp; ++x)  // every lane of the CUDA pull kernel's rows
          pullNode(om, L, coded.data(), in.data(), out.data(), x, y, z);
    std::swap(in, out);  // in: the post values of iteration t; out: of t - 1 (the arrivals of t)
    for (int z = 0; z < d.nz; ++z)
      for (int y = 0; y < d.ny; ++y)
        for (int x = 0; x < d.nx; ++x) {
          const int64_t p = d.index(x, y, z);
          ASSERT_EQ(pullArrivalTotal(L, out.data(), boundaryTotal(boundary), x, y, z), nodeTotal(a.data(), n, p))
              << "iteration " << t + 1 << " node " << x << "," << y << "," << z;
          if (!d.interior(x, y, z)) continue;
          for (int m = 0; m < kQ; ++m)  // the 19 arrivals themselves
            ASSERT_EQ(out[size_t(pullSlot(L, m, x - dir(m, 0), y - dir(m, 1), z - dir(m, 2)))], a[size_t(m * n + p)])
                << "iteration " << t + 1 << " node " << p << " m " << m;
        }
  }
}

// The CUDA backend's default scheme (shift_stream.h): streaming by index shift, collision only at
// occupied interior nodes, boundary nodes writing what they send inwards. Run here serially with
// the same CANOPY_HD functions the kernels call, it must give the push update's bits at every node
// after every iteration, on an odd-sized box whose boundary layer is occupied too (leaf and wood),
// for long enough that every direction's ring wraps around several times.
TEST(ShiftStreaming, MatchesThePushUpdateBitForBitAtEveryIteration) {
  const Dims d{13, 9, 11};
  const int64_t n = d.count();
  const std::vector<float> coded = randomCoded(n, 3);
  const OmegaSet om = makeOmegaSet(0.109, 0.891, 0.3, -1.0, 4.0);
  float boundary[kQ];
  for (int m = 0; m < kQ; ++m) boundary[m] = 0.05f * float(m + 1);
  // Reference: the push update over every node, ping-pong.
  std::vector<float> a, b;
  initPush(d, boundary, a, b);
  std::vector<float> state(a.size(), 0.f), kept(size_t(n), -1.f);
  int64_t collided = 0;
  const int iterations = 40;  // the z-directions' ring (step 117 of 1287 slots) wraps 3 times
  for (int t = 0; t < iterations; ++t) {
    stepLattice(om, d, coded, a, b);
    std::swap(a, b);
    const ShiftOffsets off = shiftOffsets(d, t);
    for (int z = 0; z < d.nz; ++z)
      for (int y = 0; y < d.ny; ++y)
        for (int x = 0; x < d.nx; ++x) {
          const int64_t p = d.index(x, y, z);
          const float c = coded[size_t(p)];
          if (!d.interior(x, y, z)) {
            if (c == 0.f) {
              shiftBoundaryNode<true>(om, d, boundary, off, c, x, y, z, state.data());
            } else {
              shiftBoundaryNode<false>(om, d, boundary, off, c, x, y, z, state.data());
            }
          } else if (c < 0.f) {
            shiftCollideNode<kWoodKind>(om, off, n, c, p, state.data(), &kept[size_t(p)]);
            ++collided;
          } else if (c != 0.f) {
            shiftCollideNode<kLeafKind>(om, off, n, c, p, state.data(), &kept[size_t(p)]);
            ++collided;
          }
        }
    const ShiftOffsets next = shiftOffsets(d, t + 1);  // (off: the offsets before the iteration)
    for (int z = 0; z < d.nz; ++z)
      for (int y = 0; y < d.ny; ++y)
        for (int x = 0; x < d.nx; ++x) {
          const int64_t p = d.index(x, y, z);
          const float want = nodeTotal(a.data(), n, p);
          if (d.interior(x, y, z)) {  // the residual's previous total, read after the iteration
            const float previous = coded[size_t(p)] != 0.f ? kept[size_t(p)] : shiftNodeTotal(state.data(), n, off, p);
            ASSERT_EQ(previous, nodeTotal(b.data(), n, p)) << "iteration " << t << " node " << p;
          }
          const float got = d.interior(x, y, z) ? shiftNodeTotal(state.data(), n, next, p) : boundaryTotal(boundary);
          ASSERT_EQ(got, want) << "iteration " << t + 1 << " node " << x << "," << y << "," << z;
          if (!d.interior(x, y, z)) continue;
          for (int m = 0; m < kQ; ++m)  // the 19 values themselves, not just their sum
            ASSERT_EQ(state[size_t(m * n + shifted(uint32_t(p), next.off[m], uint32_t(n)))], a[size_t(m * n + p)])
                << "iteration " << t + 1 << " node " << p << " direction " << m;
        }
  }
  EXPECT_GT(collided, 0);
  EXPECT_GT(nodeTotal(a.data(), n, d.index(6, 4, 5)), 0.f);  // light reached the middle
}

TEST(ShiftStreaming, OffsetsArePeriodicAndInRange) {
  const Dims d{7, 5, 6};
  const int64_t n = d.count();
  for (int64_t t : {int64_t(0), int64_t(1), int64_t(209), n - 1, n, 3 * n + 5, int64_t(1) << 40}) {
    const ShiftOffsets s = shiftOffsets(d, t), later = shiftOffsets(d, t + n);
    for (int m = 0; m < kQ; ++m) {
      ASSERT_LT(int64_t(s.off[m]), n);
      ASSERT_EQ(s.off[m], later.off[m]);
      // One more iteration moves node p's slot to node p + s_m's.
      const ShiftOffsets next = shiftOffsets(d, t + 1);
      const int64_t p = d.index(3, 2, 2);
      ASSERT_EQ(shifted(uint32_t(p + linearStep(d, m)), next.off[m], uint32_t(n)),
                shifted(uint32_t(p), s.off[m], uint32_t(n))) << m;
    }
  }
}
