// test_play_scene_light.cpp: the coarse scene light (canopy-lbsolve --scene, dissertation §4.3) in
// the player: its 19 bases relight each instance's indirect light per frame, the ambient term by
// B00 and the scattered sun term by the sun's bases weighted by the frame's sun lookup.
//
// The coarse lattices are solved in-process by the lbsolve library's scene solve (canopy::lbsolve
// with LbsolveOptions::scene, the code behind canopy-lbsolve --scene) and read by
// canopy-octreepack's scene-light reader, so that the test sees real coarse bases.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <fstream>
#include <string>
#include <vector>

#include "canopy/atomic_file.h"
#include "canopy/errors.h"
#include "canopy/lattice_dirs.h"
#include "canopy/sun_lookup.h"
#include "formats/canopy_file.h"
#include "formats/canopy_write.h"
#include "lbsolve.h"
#include "runtime/cone.h"
#include "runtime/player.h"
#include "runtime/scene.h"
#include "tests/octreepack/source_vdb.h"
#include "tests/play/scenes.h"
#include "tools/octreepack/inputs.h"

namespace pl = canopy::play;
namespace pt = canopy::play::testing;
namespace op = canopy::octreepack;

namespace {

constexpr float kRgb[3] = {1.0f, 0.5f, 0.25f};

// The "tree": a ball crown of 24^3 cells of 0.1 m (a 2.4 m box), radius 10 cells, density 0.3.
op::ModelSource crown() { return pt::sphereModel(24, 10, 0.3f); }

// canopy-lbsolve --scene over `instances` of the crown (resolution = coarse cells along the longest
// axis), read back as canopy-octreepack packs it (all 19 bases, or the one grid `grid`).
pt::SceneLightData solveSceneLight(const std::string& dir, const std::string& name, const std::vector<canopy::CanopyInstance>& instances,
                                   int resolution, const std::string& grid = "") {
  op::testing::writeSourceVdb(dir + "/crown.density.vdb", crown());
  std::string list = R"({"canopy_scene": 1, "models": [{"density": "crown.density.vdb"}], "instances": [)";
  for (size_t i = 0; i < instances.size(); ++i) {
    list += i ? ", " : "";
    list += R"({"model": 0, "matrix": [)";
    for (int k = 0; k < 12; ++k) list += std::to_string(instances[i].modelToWorld[k]) + ", ";
    list += "0, 0, 0, 1]}";
  }
  list += "]}";
  canopy::writeFileAtomic(dir + "/" + name + ".scene.json", list);
  canopy::LbsolveOptions o;
  o.scene = dir + "/" + name + ".scene.json";
  o.output = dir + "/" + name + ".scenelight.vdb";
  o.sceneResolution = resolution;
  canopy::lbsolve(o);
  const op::SceneLightSource s = op::readSceneLightVdb(o.output, grid);
  pt::SceneLightData d;
  d.header = s.header;
  d.bases = s.bases;
  d.values = s.values;
  return d;
}

// One camera for every render: in front of both crowns (+z), looking at the pair's centre.
std::string cameraFile(const std::string& dir) {
  const std::string p = dir + "/camera.json";
  std::ofstream(p) << R"({"keyframes":[{"frame":0,"position":[0,1.5,9],"target":[0,0,0],"fov":45}]})";
  return p;
}

std::vector<float> render(const std::string& file, const std::string& camera, const std::string& sun, nlohmann::json* report = nullptr) {
  pl::PlayOptions o;
  o.input = file;
  o.width = 96;
  o.height = 48;
  o.converge = true;
  o.camera = camera;
  o.sun = sun;
  o.directSun = false;  // the indirect light alone (--no-direct-sun)
  o.ambient = 0.0f;     // and of it the scattered sun alone, the term the sun's scene bases weight
  o.ground = "none";    // the crowns' own pixels (their masks are where they are opaque)
  std::vector<float> img;
  const nlohmann::json r = pl::play(o, canopy::Device{}, &img);
  if (report) *report = r;
  return img;
}

// The pixels where `img` shows matter (alpha > 0.05).
std::vector<bool> maskOf(const std::vector<float>& img) {
  std::vector<bool> m(img.size() / 4);
  for (size_t i = 0; i < m.size(); ++i) m[i] = img[4 * i + 3] > 0.05f;
  return m;
}

// Mean RGB (premultiplied, as rendered) over the pixels of `mask`.
double meanOver(const std::vector<float>& img, const std::vector<bool>& mask) {
  double s = 0;
  size_t n = 0;
  for (size_t i = 0; i < mask.size(); ++i)
    if (mask[i]) s += double(img[4 * i]) + img[4 * i + 1] + img[4 * i + 2], n += 3;
  return n ? s / double(n) : 0.0;
}

}  // namespace

// The pair builder against a hand computation. Base j's node i holds 10 j + i (2 nodes). A sun
// straight along a lattice direction puts the whole weight on that base; a light direction through
// the centroid of a lookup face's three unit vertices hits the face at its centroid, so each of the
// three bases weighs 1/3. One base (B00 alone): both factors are B00.
TEST(SceneLight, PairGridIsB00AndTheLookupWeightedSunBases) {
  const size_t nodes = 2;
  std::vector<float> values(19 * nodes);
  for (size_t j = 0; j < 19; ++j)
    for (size_t i = 0; i < nodes; ++i) values[j * nodes + i] = float(10 * j + i);
  std::vector<pl::SceneLightPair> pairs;
  canopy::sun::Weights w;
  ASSERT_TRUE(canopy::sun::lookup(0.0f, -1.0f, 0.0f, w));  // light travelling -y: B04 alone
  pl::buildSceneLightPairs(values, 19, nodes, w, pairs);
  ASSERT_EQ(pairs.size(), nodes);
  EXPECT_EQ(pairs[0].ambient, 0.0f);
  EXPECT_EQ(pairs[1].ambient, 1.0f);
  EXPECT_EQ(pairs[0].sun, 40.0f);
  EXPECT_EQ(pairs[1].sun, 41.0f);
  // Face 0 = {1, 7, 11}: the light along the sum of its unit vertices.
  float d[3] = {0, 0, 0};
  int sumOfBases = 0;
  for (int v = 0; v < 3; ++v) {
    const int b = canopy::sun::faceVertex(0, v);
    sumOfBases += b;
    for (int a = 0; a < 3; ++a) d[a] += float(canopy::lattice::dir(b, a)) / float(canopy::lattice::length(b));
  }
  ASSERT_TRUE(canopy::sun::lookup(d[0], d[1], d[2], w));
  EXPECT_EQ(w.face, 0);
  pl::buildSceneLightPairs(values, 19, nodes, w, pairs);
  for (size_t i = 0; i < nodes; ++i) {
    EXPECT_NEAR(pairs[i].sun, (10.0f * float(sumOfBases) + 3.0f * float(i)) / 3.0f, 1e-4f) << i;  // (B01 + B07 + B11) / 3
    EXPECT_EQ(pairs[i].ambient, float(i));
  }
  // B00 alone: the old static factor on both terms, whatever the sun.
  const std::vector<float> b00 = {0.25f, 0.75f};
  pl::buildSceneLightPairs(b00, 1, nodes, w, pairs);
  EXPECT_EQ(pairs[0].ambient, 0.25f);
  EXPECT_EQ(pairs[0].sun, 0.25f);
  EXPECT_EQ(pairs[1].sun, 0.75f);
  EXPECT_THROW(pl::buildSceneLightPairs(values, 19, 3, w, pairs), canopy::Error);  // 38 values are not 19 x 3
}

// HostScene::setSun relights the scene lattice per frame: the pairs follow the sun's lookup in the
// lattice's axes (world axes here, cell 2 m: the direction is unchanged), and are rebuilt (the CUDA
// backend re-uploads on lightVersion) only when the lookup changes.
TEST(SceneLight, SetSunRebuildsTheSunFactorsWhenTheSunMoves) {
  std::vector<canopy::octreepack::BuiltModel> built;
  built.push_back(canopy::octreepack::buildOctree(pt::sphereModel(8, 3, 0.3f), "s"));
  canopy::CanopyWriteInput in;
  in.models.push_back({built[0].record, &built[0].tiles, &built[0].bricks});
  in.instances = {pt::instanceAt(0, 0, 0, 0)};
  in.hasSceneLight = true;
  const double m[12] = {2, 0, 0, -3, 0, 2, 0, -3, 0, 0, 2, -3};
  for (int i = 0; i < 12; ++i) in.sceneLight.indexToWorld[i] = m[i];
  for (int a = 0; a < 3; ++a) in.sceneLight.min[a] = 0, in.sceneLight.dim[a] = 3;
  in.sceneLightBases = 19;
  for (int j = 0; j < 19; ++j)
    for (int i = 0; i < 27; ++i) in.sceneLightValues.push_back(float(j) + 0.01f * float(i));
  const std::vector<unsigned char> bytes = canopy::writeCanopyBytes(std::move(in));
  const canopy::CanopyFile f = canopy::CanopyFile::fromMemory(bytes.data(), bytes.size(), "pairs.canopy");
  EXPECT_EQ(f.header().minor, 2);
  ASSERT_EQ(f.sceneLightBases(), 19u);
  pl::HostScene s = pl::buildScene(f);
  EXPECT_EQ(s.lightBases, 19u);
  s.setSun(pl::v3(0, 1, 0));  // light travelling -y: B04
  const uint64_t v = s.lightVersion;
  ASSERT_EQ(s.lightPairs.size(), 27u);
  for (int i = 0; i < 27; ++i) {
    EXPECT_EQ(s.lightPairs[size_t(i)].ambient, 0.01f * float(i));
    EXPECT_EQ(s.lightPairs[size_t(i)].sun, 4.0f + 0.01f * float(i));
  }
  s.setSun(pl::v3(0, 1, 0));
  EXPECT_EQ(s.lightVersion, v);  // the same sun: nothing rebuilt
  s.setSun(pl::v3(-1, 0, 0));  // light travelling +x: B01
  EXPECT_GT(s.lightVersion, v);
  for (int i = 0; i < 27; ++i) EXPECT_EQ(s.lightPairs[size_t(i)].sun, 1.0f + 0.01f * float(i));
  // The SceneView points at the pairs.
  EXPECT_EQ(pl::hostSceneView(s).light.values, s.lightPairs.data());
}

// Two crowns side by side along x (their boxes touching), each lit with LB light, and the coarse
// scene lattice solved over both; rendered with the sun's direct term and the ambient light off (the
// scattered sun alone). Each crown is compared, over its own pixels, with the same crown alone (its
// own scene lattice, the same cell and the same node positions: resolution 16 over the pair's
// 4.8 m, 8 over one crown's 2.4 m), under the same camera and sun:
//   - sun low from A's side (-x): B lies in A's sun shadow and receives less scattered light than
//     alone, A about as much as alone;
//   - the sun rotated to the other side (+x): the shadowed crown changes (A now below its alone
//     value, B back near its own).
// Measured (CPU, 2026-12-04): B/alone 0.689 and A/alone 1.033 with the sun from -x (A gains a little
// of the light B scatters back towards the sun), and mirrored from +x (A 0.689, B 1.033). The
// bounds (below 0.85; above 0.97) leave room for other solver parameters. With B00 alone packed
// (the static factor before format 1.2, on every term) the ratios do not depend on the sun's side
// (measured 1.007 for both crowns under both suns: they differ by less than 1e-3).
TEST(SceneLight, CrownInItsNeighboursSunShadowReceivesLessScatteredLight) {
  const std::string dir = pt::tmpDir("scene-light");
  const auto A = pt::instanceAt(0, -1.2f, 0, 0), B = pt::instanceAt(0, 1.2f, 0, 0);
  const pt::SceneLightData pair = solveSceneLight(dir, "pair", {A, B}, 16);
  const pt::SceneLightData aloneA = solveSceneLight(dir, "aloneA", {A}, 8);
  const pt::SceneLightData aloneB = solveSceneLight(dir, "aloneB", {B}, 8);
  ASSERT_EQ(pair.bases, 19u);
  EXPECT_NEAR(pair.header.indexToWorld[0], 0.3, 1e-6);  // the same cell in all three lattices
  EXPECT_NEAR(aloneA.header.indexToWorld[0], 0.3, 1e-6);
  const auto light = pt::rampLight(kRgb);
  const std::string pairFile = dir + "/pair.canopy", aFile = dir + "/aloneA.canopy", bFile = dir + "/aloneB.canopy";
  pt::writeLitScene(pairFile, {crown()}, {light}, {A, B}, true, &pair);
  pt::writeLitScene(aFile, {crown()}, {light}, {A}, true, &aloneA);
  pt::writeLitScene(bFile, {crown()}, {light}, {B}, true, &aloneB);
  EXPECT_EQ(canopy::CanopyFile::open(pairFile).sceneLightBases(), 19u);  // the sun bases (SceneSunLight, 1.2 and later)
  const std::string cam = cameraFile(dir);

  // The same files with B00 alone (canopy-octreepack --scene-light-grid B00).
  pt::SceneLightData pair1 = pair, aloneA1 = aloneA, aloneB1 = aloneB;
  for (pt::SceneLightData* d : {&pair1, &aloneA1, &aloneB1}) {
    d->values.resize(d->values.size() / 19);
    d->bases = 1;
  }
  const std::string pair1File = dir + "/pair-b00.canopy", a1File = dir + "/aloneA-b00.canopy", b1File = dir + "/aloneB-b00.canopy";
  pt::writeLitScene(pair1File, {crown()}, {light}, {A, B}, true, &pair1);
  pt::writeLitScene(a1File, {crown()}, {light}, {A}, true, &aloneA1);
  pt::writeLitScene(b1File, {crown()}, {light}, {B}, true, &aloneB1);

  struct Ratios {
    double a, b;
  };
  auto ratios = [&](const std::string& pf, const std::string& af, const std::string& bf, const char* sun) {
    nlohmann::json r;
    const std::vector<float> both = render(pf, cam, sun, &r);
    EXPECT_EQ(int(r["scene_light_bases"]), pf == pairFile ? 19 : 1);
    const std::vector<float> a = render(af, cam, sun), b = render(bf, cam, sun);
    const std::vector<bool> ma = maskOf(a), mb = maskOf(b);
    size_t na = 0, nb = 0;
    for (size_t i = 0; i < ma.size(); ++i) {
      EXPECT_FALSE(ma[i] && mb[i]) << "the crowns overlap on screen at pixel " << i;
      na += ma[i], nb += mb[i];
    }
    EXPECT_GT(na, 100u);
    EXPECT_GT(nb, 100u);
    EXPECT_GT(meanOver(a, ma), 0.01);
    return Ratios{meanOver(both, ma) / meanOver(a, ma), meanOver(both, mb) / meanOver(b, mb)};
  };
  const char* fromA = "-1,0.3,0";  // towards the sun: low, on A's side
  const char* fromB = "1,0.3,0";
  const Ratios lowA = ratios(pairFile, aFile, bFile, fromA), lowB = ratios(pairFile, aFile, bFile, fromB);
  std::printf("19 bases: sun from A's side: A %.3f B %.3f of alone; from B's side: A %.3f B %.3f\n", lowA.a, lowA.b, lowB.a, lowB.b);
  EXPECT_LT(lowA.b, 0.85);  // B in A's sun shadow
  EXPECT_GT(lowA.a, 0.97);  // A in the open
  EXPECT_LT(lowB.a, 0.85);  // the sun rotated: now A is in B's shadow
  EXPECT_GT(lowB.b, 0.97);  // and B back near alone
  const Ratios staticA = ratios(pair1File, a1File, b1File, fromA), staticB = ratios(pair1File, a1File, b1File, fromB);
  std::printf("B00 alone: sun from A's side: A %.3f B %.3f; from B's side: A %.3f B %.3f\n", staticA.a, staticA.b, staticB.a, staticB.b);
  EXPECT_NEAR(staticA.b, staticB.b, 1e-3);  // the static factor does not see where the sun is
  EXPECT_NEAR(staticA.a, staticB.a, 1e-3);
}
