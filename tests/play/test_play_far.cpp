// The far field (cone.h farFieldStep): beyond where a cone's footprint exceeds every instance's
// coarsest voxel, a prefiltered scene volume stands in for the instances. Its image against the
// per-instance render, its cost against the number of instances it stands for, and where it
// changes nothing.
#include <cmath>
#include <fstream>

#include <gtest/gtest.h>

#include "formats/canopy_file.h"
#include "runtime/player.h"
#include "runtime/scene.h"
#include "tests/octreepack/synthetic.h"
#include "tests/play/scenes.h"
#include "tests/play/views.h"

namespace pl = canopy::play;
namespace pt = canopy::play::testing;

namespace {

// A stand of nx x nz synthetic plants (two species, yawed, 0.8 tall), `spacing` apart, from x = x0 on.
std::vector<canopy::CanopyInstance> stand(int nx, int nz, float spacing, float x0) {
  std::vector<canopy::CanopyInstance> inst;
  for (int i = 0; i < nx; ++i)
    for (int k = 0; k < nz; ++k) {
      const int n = i * nz + k;
      inst.push_back(pt::instanceAt(uint32_t(n % 2), x0 + float(i) * spacing + 0.3f * float(n % 3), 0.0f,
                                    (float(k) - 0.5f * float(nz - 1)) * spacing + 0.2f * float(n % 5), 0.5f, 0.7f * float(n)));
    }
  return inst;
}

std::vector<canopy::octreepack::ModelSource> species() {
  // 64 cells (of 0.05, instanced at half size): the coarsest level's voxel (8 cells) is the finest node
  return {canopy::octreepack::testing::syntheticPlant(64, 0, "a", 8), canopy::octreepack::testing::syntheticPlant(64, 0, "b", 6)};
}

// A stand of 12 x 9 plants 1.2 apart, x from -6.
const std::string& standFile() {
  static const std::string path = [] {
    const std::string p = pt::tmpDir("scenes") + "/far-stand.canopy";
    pt::writeScene(p, species(), stand(12, 9, 1.2f, -6.0f));
    return p;
  }();
  return path;
}

// A camera at x = -12 looking along +x across the stand, at eye height (0.9, the crowns' tops) or
// from above (3), as a keyframe file.
std::string lowView(const std::string& name, float height = 0.9f) {
  const std::string path = pt::tmpDir("scenes") + "/" + name + ".json";
  std::ofstream(path) << R"({"keyframes":[{"frame":0,"position":[-12,)" << height << R"(,0.3],"target":[10,0.4,-0.5],"fov":60}]})";
  return path;
}

// The RMS of the RGB difference over the mean RGB of the reference's covered pixels (alpha > 0.01):
// bench-image-diff's "relative".
double relativeRms(const std::vector<float>& got, const std::vector<float>& ref) {
  double d = 0.0, mean = 0.0;
  size_t covered = 0;
  for (size_t i = 0; i < ref.size(); i += 4) {
    for (int c = 0; c < 3; ++c) d += double(got[i + c] - ref[i + c]) * (got[i + c] - ref[i + c]);
    if (ref[i + 3] > 0.01f) {
      mean += (ref[i] + ref[i + 1] + ref[i + 2]) / 3.0;
      ++covered;
    }
  }
  return covered ? std::sqrt(d / double(ref.size() / 4 * 3)) / (mean / double(covered)) : 0.0;
}

}  // namespace

// The far field's grid: one voxel of margin around the scene's bounds, the voxel the coarsest
// level's voxel of the widest instance (these plants: 64 cells of 0.025 at half size, so 8 cells:
// 0.2), every border voxel empty, matter inside, extinction x albedo at most the extinction.
TEST(FarField, GridCoversTheSceneWithTheCoarsestVoxelAndEmptyBorders) {
  const canopy::CanopyFile f = canopy::CanopyFile::open(standFile());
  const pl::HostScene scene = pl::buildScene(f);
  pl::FarFieldView g = pl::planFarField(scene);
  EXPECT_FLOAT_EQ(g.voxel, 0.2f);  // 8 cells of 0.025
  EXPECT_EQ(scene.far.voxel, g.voxel);  // buildScene's plan
  for (int a = 0; a < 3; ++a) {
    EXPECT_LE(g.lo[a], scene.boundsLo[a] - 0.99f * g.voxel) << a;
    EXPECT_GE(g.lo[a] + float(g.dim[a] - 1) * g.voxel, scene.boundsHi[a] + 0.99f * g.voxel) << a;
  }
  const int64_t n = int64_t(g.dim[0]) * g.dim[1] * g.dim[2];
  std::vector<float> values(size_t(n) * pl::kFarFieldChannels);
  g.values = values.data();
  pl::SceneView v = pl::hostSceneView(scene);
  v.shade = pl::shadeParams(pl::PlayOptions{});
  for (int64_t i = 0; i < n; ++i) pl::buildFarFieldVoxel(v, g, i);
  double mass = 0.0, border = 0.0;
  for (int64_t i = 0; i < n; ++i) {
    const int x = int(i % g.dim[0]), y = int((i / g.dim[0]) % g.dim[1]), z = int(i / (int64_t(g.dim[0]) * g.dim[1]));
    const float* c = values.data() + pl::kFarFieldChannels * i;
    ASSERT_GE(c[0], 0.0f);
    for (int ch = 1; ch < 4; ++ch) ASSERT_LE(c[ch], c[0] * 1.0001f + 1e-6f) << "albedo above 1";  // k x albedo <= k
    mass += c[0];
    if (x == 0 || y == 0 || z == 0 || x == g.dim[0] - 1 || y == g.dim[1] - 1 || z == g.dim[2] - 1) border += c[0];
  }
  EXPECT_GT(mass, 0.0);
  EXPECT_EQ(border, 0.0);
}

// Where no cone reaches the far field's start (a close view), the image is the per-instance one
// bit for bit; an explicit start beyond the scene too.
TEST(FarField, ChangesNothingWhereNoConeReachesIt) {
  pl::PlayOptions o = pt::convergedView(standFile(), 48, 32, lowView("far-low"));
  o.farField = "off";
  const std::vector<float> off = pt::render(o);
  o.farField = "1000";
  EXPECT_EQ(pt::render(o), off);
  // 320 x 192: the footprint reaches the 0.2 voxel at t = 0.2 / (2 tan 30deg / 192) = 33, beyond
  // the stand's far end (about 20 from the eye)
  o.width = 320, o.height = 192;
  o.farField = "off";
  const std::vector<float> offLarge = pt::render(o);
  o.farField = "auto";
  o.countWork = true;
  nlohmann::json report;
  EXPECT_EQ(pt::render(o, &report), offLarge);
  EXPECT_EQ(double(report["work"]["far_steps"]), 0.0);
  EXPECT_FLOAT_EQ(float(report["far_field"]["voxel"]), 0.2f);
}

// The 2 x 2 mean of a 2w x 2h image: a supersampled reference of the w x h one.
std::vector<float> downsample2(const std::vector<float>& big, int w, int h) {
  std::vector<float> out(size_t(w) * h * 4);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x)
      for (int c = 0; c < 4; ++c) {
        float s = 0.0f;
        for (int j = 0; j < 4; ++j) s += big[4 * (size_t(2 * y + j / 2) * size_t(2 * w) + size_t(2 * x + j % 2)) + size_t(c)];
        out[4 * (size_t(y) * w + x) + size_t(c)] = 0.25f * s;
      }
  return out;
}

// From 48 x 32 pixels (the footprint reaches the 0.2 voxel at t = 0.2 / 0.036 = 5.5 on the axis:
// most of the stand) the far field stands in for the instances beyond. Its image is within 20 %
// RMS of the per-instance one (relative to the covered pixels' mean RGB; measured 15 %), alpha
// within 0.08 RMS (measured 0.05): a view that skims the crowns' tops, where every difference is a
// silhouette a voxel (a pixel) taller or shorter. It is no farther from a 2 x 2 supersampled
// per-instance reference than the per-instance frame itself (measured 13.7 % against 20.0 %; one
// level coarser, --lod-bias -1, is 14 % from the per-instance frame). The instances beyond its
// start are not evaluated: fewer instance segments. Rays that end before the start (on the ground
// near the eye) give the per-instance pixels bit for bit.
TEST(FarField, StandsInForTheInstancesBeyondItsStart) {
  pl::PlayOptions o = pt::convergedView(standFile(), 48, 32, lowView("far-low"));
  o.countWork = true;
  o.farField = "off";
  nlohmann::json offReport, farReport;
  const std::vector<float> off = pt::render(o, &offReport);
  o.farField = "auto";
  const std::vector<float> far = pt::render(o, &farReport);
  ASSERT_EQ(far.size(), off.size());
  pl::PlayOptions big = o;
  big.farField = "off";
  big.countWork = false;
  big.width = 96, big.height = 64;
  const std::vector<float> reference = downsample2(pt::render(big), 48, 32);
  double alpha = 0.0;
  for (size_t i = 3; i < off.size(); i += 4) alpha += double(far[i] - off[i]) * (far[i] - off[i]);
  alpha = std::sqrt(alpha / double(off.size() / 4));
  const double rel = relativeRms(far, off), farToRef = relativeRms(far, reference), offToRef = relativeRms(off, reference);
  const double segOff = double(offReport["work"]["segments"]), segFar = double(farReport["work"]["segments"]);
  std::printf("relative RMS %.4f, alpha RMS %.4f; to the supersampled reference: far field %.4f, per instance %.4f; segments %.0f -> %.0f, far steps %.0f\n",
              rel, alpha, farToRef, offToRef, segOff, segFar, double(farReport["work"]["far_steps"]));
  // the rows whose rays meet the ground before the far field's start (below 9.4 degrees under the
  // horizon: the ground 0.9 below the eye, the start 5.5 away) are the per-instance ones bit for
  // bit, with the far field built and in the view
  for (size_t i = size_t(4 * 48 * 22); i < off.size(); ++i) ASSERT_EQ(far[i], off[i]) << "pixel " << i / 4;
  EXPECT_LT(rel, 0.2);
  EXPECT_LT(alpha, 0.08);
  EXPECT_LE(farToRef, offToRef);
  EXPECT_GT(double(farReport["work"]["far_steps"]), 0.0);
  EXPECT_LT(segFar, 0.8 * segOff);
}

// A ray's cost beyond the far field's start no longer depends on how many instances lie there: the
// same stand with a second one of 24 x 9 plants behind it (x from 9.6, every plant farther than the
// start for every pixel), seen from above, evaluates the same instance
// segments with the far field (within 2 %: the instance grid's cells, which end steps, are the
// new scene's; measured 5021 -> 5049), and the far field's steps grow only with the grid's
// extent; without it the segments grow with the plants (measured 16739 -> 17655: most rays end
// in the first stand or on the ground), by more than ten times as much.
TEST(FarField, CostBeyondItsStartDoesNotGrowWithTheInstancesThere) {
  const std::string deep = pt::tmpDir("scenes") + "/far-deep.canopy";
  std::vector<canopy::CanopyInstance> inst = stand(12, 9, 1.2f, -6.0f), behind = stand(24, 9, 1.2f, 9.6f);
  inst.insert(inst.end(), behind.begin(), behind.end());
  pt::writeScene(deep, species(), inst);
  pl::PlayOptions o = pt::convergedView(standFile(), 48, 32, lowView("far-above", 3.0f));
  o.countWork = true;
  nlohmann::json a, b, c, d;
  pt::render(o, &a);
  o.input = deep;
  pt::render(o, &b);
  o.farField = "off";
  pt::render(o, &c);
  o.input = standFile();
  pt::render(o, &d);
  const double segA = double(a["work"]["segments"]), segB = double(b["work"]["segments"]);
  const double segOffA = double(d["work"]["segments"]), segOffB = double(c["work"]["segments"]);
  std::printf("with the far field: segments %.0f -> %.0f, far steps %.0f -> %.0f; without: segments %.0f -> %.0f\n", segA, segB,
              double(a["work"]["far_steps"]), double(b["work"]["far_steps"]), segOffA, segOffB);
  EXPECT_LT(std::fabs(segB - segA), 0.02 * segA);
  EXPECT_GT(segOffB - segOffA, 10.0 * std::fabs(segB - segA));
  EXPECT_GT(double(b["work"]["far_steps"]), double(a["work"]["far_steps"]));
}
