// test_play_ground.cpp: the ground plane (cone.h groundHit/groundRadiance, --ground): where auto
// puts it, its shading against the closed form, the crowns' shadow on it (map and cones), and that
// it cuts the scene without changing anything a ray meets before it. And the scene's other
// start-up geometry: an instance's march extent (the box of its model's leaves with matter).
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "canopy/device.h"
#include "formats/canopy_file.h"
#include "runtime/player.h"
#include "runtime/scene.h"
#include "tests/play/scenes.h"
#include "tests/play/views.h"

namespace pl = canopy::play;
namespace pt = canopy::play::testing;

namespace {

using pt::render;

// The ball of test_play: 48^3 lattice, 0.1 m cells, radius 18 cells, density 0.05, centred on the
// model origin.
constexpr int kEdge = 48;
constexpr float kRadius = 18.0f, kDensity = 0.05f, kCell = 0.1f;

const canopy::octreepack::ModelSource& ball() {
  static const canopy::octreepack::ModelSource s = pt::sphereModel(kEdge, kRadius, kDensity, kCell);
  return s;
}

// The model-space height of the ball's lowest matter: the bottom face of its lowest occupied cell.
double ballBaseModelY() {
  int minJ = kEdge;
  for (const auto& c : ball().cells) minJ = std::min(minJ, c.ijk[1]);
  return (double(minJ) - 0.5 - 0.5 * (kEdge - 1)) * kCell;
}

const std::string& oneBall() {
  static const std::string p = [] {
    const std::string f = pt::tmpDir("ground") + "/ball.canopy";
    pt::writeScene(f, {ball()}, {pt::instanceAt(0, 0, 0, 0)});
    return f;
  }();
  return p;
}

// One keyframe: a fixed camera.
std::string cameraFile(const char* name, const float pos[3], const float target[3], float fov) {
  const std::string p = pt::tmpDir("ground") + "/" + name + ".json";
  char buf[256];
  std::snprintf(buf, sizeof buf, R"({"keyframes":[{"frame":0,"position":[%.9g,%.9g,%.9g],"target":[%.9g,%.9g,%.9g],"fov":%g}]})",
                pos[0], pos[1], pos[2], target[0], target[1], target[2], fov);
  std::ofstream(p) << buf;
  return p;
}

// albedo x (sun x cos + ambient x 1): the open ground without a scene light.
float openGround(const pl::PlayOptions& o, int c, float cosSun, float sunT = 1.0f) {
  return o.groundAlbedo[c] * (o.sunIntensity * cosSun * sunT + o.ambient);
}

}  // namespace

// auto: the lowest instance base, i.e. the world height of the bottom face of the lowest occupied
// cell over instances (found in the ball's bricks: its lowest cell row lies inside a finest node),
// with a scaled and turned instance lowest.
TEST(Ground, AutoSitsAtTheLowestInstanceBase) {
  const std::string f = pt::tmpDir("ground") + "/three.canopy";
  pt::writeScene(f, {ball()}, {pt::instanceAt(0, 0, 0, 0), pt::instanceAt(0, 5, 2, 0), pt::instanceAt(0, -5, 1, 0, 2.0f, 0.7f)});
  const double base = ballBaseModelY();
  EXPECT_NEAR(base, -1.8, 1e-6);  // row 6 of 48: (6 - 0.5 - 23.5) x 0.1
  const double want = std::min({0.0 + base, 2.0 + base, 1.0 + 2.0 * base});
  const pl::HostScene scene = pl::buildScene(canopy::CanopyFile::open(f));
  EXPECT_NEAR(scene.groundBase, want, 1e-5);
  nlohmann::json r;
  const float pos[3] = {0, 6, -12}, target[3] = {0, 0, 0};
  render(pt::convergedView(f, 8, 8, cameraFile("three", pos, target, 50)), &r);
  ASSERT_TRUE(r["ground"].is_object()) << r.dump();
  EXPECT_NEAR(double(r["ground"]["y"]), want, 1e-5);
  EXPECT_EQ(r["ground"]["from"], "auto");
  pl::PlayOptions o = pt::convergedView(f, 8, 8, cameraFile("three", pos, target, 50));
  o.ground = "none";
  render(o, &r);
  EXPECT_TRUE(r["ground"].is_null());
  o.ground = "-0.25";
  render(o, &r);
  EXPECT_FLOAT_EQ(float(r["ground"]["y"]), -0.25f);
  EXPECT_EQ(r["ground"]["from"], "option");
}

// Open ground far from the ball: every pixel is opaque and equals albedo x (sun x cos + ambient),
// with the shadow map, with shadow cones and without shadows (nothing lies between it and the sun).
TEST(Ground, OpenGroundIsAlbedoTimesSunCosinePlusAmbient) {
  const float base = float(ballBaseModelY());
  const float pos[3] = {30, 3, 0}, target[3] = {34, base, 0.5f};
  const std::string cam = cameraFile("open", pos, target, 10);
  for (const char* shadows : {"map", "cone", "off"}) {
    pl::PlayOptions o = pt::convergedView(oneBall(), 12, 9, cam);
    o.sun = "0.5,1,0.3";
    if (std::string(shadows) == "off") o.shadows = false;
    else o.shadowMethod = shadows;
    o.groundAlbedo[0] = 0.3f, o.groundAlbedo[1] = 0.25f, o.groundAlbedo[2] = 0.1f;
    const float cosSun = float(1.0 / std::sqrt(0.25 + 1.0 + 0.09));
    const std::vector<float> img = render(o);
    for (size_t p = 0; p < img.size() / 4; ++p) {
      ASSERT_EQ(img[4 * p + 3], 1.0f) << shadows << " pixel " << p;
      for (int c = 0; c < 3; ++c) ASSERT_NEAR(img[4 * p + size_t(c)], openGround(o, c, cosSun), 2e-6f) << shadows << " pixel " << p;
    }
  }
}

// The ball's shadow on the ground: the sun at 45 degrees along +x, so the shadow lies on the -x
// side; the view is of the ground at x = -3 (its sun line crosses the ball's height at x = -1.2 and
// passes 0.85 m from its centre: an optical depth above 6). Shadowed pixels keep the sky term and lose nearly all of the direct
// one, with the map as with shadow cones (the reference), which agree at the view's centre.
TEST(Ground, TakesTheCrownsShadowFromTheMapAndFromShadowCones) {
  const float base = float(ballBaseModelY());
  const float pos[3] = {-6, 3, 0.0f}, target[3] = {-3, base, 0.0f};
  const std::string cam = cameraFile("shadow", pos, target, 12);
  const int w = 9, h = 9, centre = 4 * (h / 2 * w + w / 2);
  const float cosSun = float(std::sqrt(0.5));
  std::vector<float> byMethod[2];
  for (int k = 0; k < 2; ++k) {
    pl::PlayOptions o = pt::convergedView(oneBall(), w, h, cam);
    o.sun = "1,1,0";
    o.shadowMethod = k == 0 ? "map" : "cone";
    byMethod[k] = render(o);
    for (int c = 0; c < 3; ++c) {
      const float v = byMethod[k][size_t(centre + c)];
      EXPECT_GE(v, openGround(o, c, cosSun, 0.0f) - 1e-6f) << o.shadowMethod;  // the sky term stays
      EXPECT_LE(v, openGround(o, c, cosSun, 0.05f)) << o.shadowMethod;        // >= 95 % of the sun is blocked
    }
  }
  for (int c = 0; c < 3; ++c) EXPECT_NEAR(byMethod[0][size_t(centre + c)], byMethod[1][size_t(centre + c)], 0.01f);
  pl::PlayOptions o = pt::convergedView(oneBall(), w, h, cam);
  o.sun = "1,1,0";
  o.shadows = false;
  const std::vector<float> lit = render(o);
  for (int c = 0; c < 3; ++c) EXPECT_NEAR(lit[size_t(centre + c)], openGround(o, c, cosSun), 2e-6f);
}

// A ground through the ball's centre, seen from just above it: every ray that goes down ends on it
// (opaque); the rays that go up never reach it and are bit for bit those of the frame without a
// ground, the ball's upper half included. From below the plane the ground is not seen at all.
TEST(Ground, CutsTheSceneAndChangesNothingBeforeIt) {
  const float pos[3] = {0, 0.3f, -8}, target[3] = {0, 0.3f, 0};
  const std::string cam = cameraFile("level", pos, target, 40);
  const int w = 32, h = 24;
  pl::PlayOptions o = pt::convergedView(oneBall(), w, h, cam);
  o.ground = "0";
  const std::vector<float> cut = render(o);
  o.ground = "none";
  const std::vector<float> none = render(o);
  int below = 0, ballRows = 0;
  for (int y = 0; y < h; ++y) {
    const bool down = y >= h / 2;  // the rows below the view axis (which is level)
    for (int x = 0; x < w; ++x) {
      const size_t p = size_t(4 * (y * w + x));
      if (down) {
        ASSERT_EQ(cut[p + 3], 1.0f) << x << "," << y;
        ++below;
      } else {
        for (int c = 0; c < 4; ++c) ASSERT_EQ(cut[p + size_t(c)], none[p + size_t(c)]) << x << "," << y;
        ballRows += none[p + 3] > 0.5f;
      }
    }
  }
  EXPECT_GT(below, 0);
  EXPECT_GT(ballRows, 10);  // the ball's upper half is in view
  o.ground = "5";           // above the eye: not seen
  const std::vector<float> above = render(o);
  EXPECT_EQ(above, none);
}

// The march's extent of an instance is the box of its model's leaves with matter, not the lattice
// (a crown's lattice is a cube around the tree's height): a small block of matter in one corner of a
// 48^3 lattice (cells 10..13, inside the finest node [8, 16)) gives the unit box [8, 16) / 64 and
// the world box of those cells, while the scene's bounds stay the lattice's (framing, shadow map).
TEST(Scene, MarchExtentIsTheBoxOfTheLeavesWithMatter) {
  canopy::octreepack::ModelSource corner = pt::sphereModel(kEdge, 0.0f, kDensity, kCell);  // the lattice, no cell
  for (int k = 10; k <= 13; ++k)
    for (int j = 10; j <= 13; ++j)
      for (int i = 10; i <= 13; ++i) corner.cells.push_back({{i, j, k}, 0.3f, 0.0f, {0.5f, 0.5f, 0.5f}});
  const std::string f = pt::tmpDir("ground") + "/corner.canopy";
  pt::writeScene(f, {corner}, {pt::instanceAt(0, 1, 2, 3)});
  const pl::HostScene scene = pl::buildScene(canopy::CanopyFile::open(f));
  ASSERT_EQ(scene.instances.size(), 1u);
  const pl::InstanceView& v = scene.instances[0];
  const double c = 0.5 * (kEdge - 1);
  for (int a = 0; a < 3; ++a) {
    EXPECT_FLOAT_EQ(v.unitLo[a], 8.0f / 64.0f) << a;
    EXPECT_FLOAT_EQ(v.unitHi[a], 16.0f / 64.0f) << a;
    const double at = a == 0 ? 1.0 : (a == 1 ? 2.0 : 3.0);
    EXPECT_NEAR(v.boundsLo[a], at + (7.5 - c) * kCell, 1e-5) << a;    // cell 8's low face
    EXPECT_NEAR(v.boundsHi[a], at + (15.5 - c) * kCell, 1e-5) << a;   // cell 15's high face
    EXPECT_NEAR(scene.boundsLo[a], at - (c + 0.5) * kCell, 1e-5) << a;  // the lattice's
    EXPECT_NEAR(scene.boundsHi[a], at + (c + 0.5) * kCell, 1e-5) << a;
  }
}

// docs/play.md, "Choosing a plant's detail for a close-up": two lenses framing the ball's height to
// the frame height see its centre's voxels at the same width; the wider lens comes nearer, so its
// front's voxels are wider (by d / (d - r) of each), and each stays within its formula.
TEST(LevelOfDetail, TheLensDecidesTheCloseUpsWidestVoxel) {
  const double r = kRadius * kCell;  // 1.8 m
  double widest[2] = {0, 0};
  for (const int i : {0, 1}) {
    const double fov = i == 0 ? 40.0 : 20.0, half = fov * M_PI / 360.0;
    const double distance = (r + kCell) / std::tan(half), pixelAngle = 2.0 * std::tan(half) / 64.0;
    pl::PlayOptions o = pt::convergedView(oneBall(), 64, 64,
                                          "orbit:azimuth=0,elevation=0,turns=0,fov=" + std::to_string(fov) + ",distance=" + std::to_string(distance));
    o.ground = "none";
    o.countWork = true;
    nlohmann::json rep;
    render(o, &rep);
    const nlohmann::json& v = rep["work"]["voxel_px"];
    ASSERT_GT(uint64_t(v["segments"]), 100u) << fov;
    widest[i] = double(v["max"]);
    // the formula at the lattice box's front face: shading segments begin where a brick does, and the
    // ball's outer bricks reach the box
    const double front = kCell / ((distance - 0.5 * kEdge * kCell) * pixelAngle);
    std::printf("fov %.0f at %.2f m: widest voxel %.3f px (front %.3f px)\n", fov, distance, widest[i], front);
    EXPECT_LE(widest[i], front * 1.01) << fov;
    EXPECT_GT(widest[i], 0.8 * front) << fov;
  }
  EXPECT_GT(widest[0], widest[1] * 1.05);
}

// The level of detail rule (docs/play.md, "Level of detail"): a shading segment samples the
// coarsest level whose voxel is no wider than the pixel's footprint there, and never finer than the
// finest. Seen from far (a pixel wider than the ball's 0.1 m cells at every sample), every voxel is
// at most a pixel wide (measured max 0.61); seen close (0.4 m from its front, 64 px over 40 degrees:
// a pixel is 4.5 mm there), the finest level is the limit and its voxels cover up to ~22 pixels
// (measured max 25.5 over the ball's depth), which the statistic reports (countVoxelFootprint; the
// CPU's --count-work). The statistic counts the level the rule chooses (segmentLevel, as the
// renderer calls it), not a coarser resident ancestor used while pages stream: the frames here are
// converged, where the two are the same.
TEST(LevelOfDetail, VoxelIsNoWiderThanThePixelWhereTheLatticeAllows) {
  const double pixelAngle = 2.0 * std::tan(20.0 * M_PI / 180.0) / 64.0;
  for (const double distance : {60.0, 2.2}) {
    pl::PlayOptions o = pt::convergedView(oneBall(), 64, 64, "orbit:azimuth=0,elevation=0,fov=40,turns=0,distance=" + std::to_string(distance));
    o.ground = "none";
    o.countWork = true;
    nlohmann::json r;
    render(o, &r);
    const nlohmann::json& v = r["work"]["voxel_px"];
    std::printf("distance %.1f: %s\n", distance, v.dump().c_str());
    ASSERT_GT(uint64_t(v["segments"]), 100u);
    if (distance > 10.0) {
      EXPECT_EQ(uint64_t(v["segments"]), uint64_t(v["at_most_1"]));
      EXPECT_LE(double(v["max"]), 1.0);
    } else {
      // the front of the ball is 2.2 - 1.8 = 0.4 m away: a 0.1 m cell over 0.4 x pixelAngle, at most
      const double most = kCell / ((distance - kRadius * kCell - kCell) * pixelAngle);
      EXPECT_GT(double(v["fraction_above_1_5"]), 0.5);
      EXPECT_GT(double(v["max"]), 0.5 * most);
      EXPECT_LE(double(v["max"]), most * 1.01);
      EXPECT_EQ(uint64_t(v["at_most_1"]), 0u);  // every sample is closer than 0.1 / pixelAngle = 8.8 m
    }
  }
}
