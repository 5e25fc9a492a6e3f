// resident.h: a SceneView over a packed file with every page resident (pool slot = page index), for
// tests that call runtime/cone.h's per-sample functions directly (the descent, a segment's light,
// a shadow cone).
#pragma once
#include <cstdint>
#include <vector>

#include "formats/canopy_file.h"
#include "runtime/player.h"
#include "runtime/scene.h"

namespace canopy::play::testing {

struct ResidentPages {
  std::vector<unsigned char> pool;
  std::vector<int32_t> pageSlot;
  std::vector<uint32_t> slotUsed, pageWanted;

  ResidentPages() = default;
  explicit ResidentPages(const CanopyFile& f) {
    const uint32_t pages = f.pageCount(), bytes = f.header().pageBytes;
    pool.resize(size_t(pages) * bytes);
    for (uint32_t p = 0; p < pages; ++p) {
      f.readPage(p, pool.data() + size_t(p) * bytes);
      pageSlot.push_back(int32_t(p));
    }
    slotUsed.assign(pages, 0);
    pageWanted.assign(pages, 0);
  }
  // The scene's view with these pages as its cache (stamp 1).
  SceneView view(const HostScene& scene) {
    SceneView v = hostSceneView(scene);
    v.pool = pool.data();
    v.pageSlot = pageSlot.data();
    v.slotUsed = slotUsed.data();
    v.pageWanted = pageWanted.data();
    v.stamp = 1;
    return v;
  }
};

// The scene view of the first frame of o (its camera, sun and ground; shadows off) with every page
// resident, for tests that call renderPixel* directly.
struct FrameView {
  CanopyFile f;
  HostScene scene;
  ShadeParams shade;
  ResidentPages pages;
  SceneView v{};
  CameraView camera{};

  explicit FrameView(const PlayOptions& o) : f(CanopyFile::open(o.input)), scene(buildScene(f)), pages(f) {
    const std::vector<FrameSetup> plan = framePlan(o, scene);
    shade = shadeParams(o);
    shade.shadows = kShadowsOff;
    shade.toSun = plan[0].toSun;
    setGround(o, scene, shade);
    scene.setSun(shade.toSun);
    v = pages.view(scene);
    v.shade = shade;
    camera = plan[0].camera;
  }
  FrameView(const FrameView&) = delete;
  FrameView& operator=(const FrameView&) = delete;
};

}  // namespace canopy::play::testing
