// resident.h: a SceneView over a packed file with every page resident (pool slot = page index), for
// tests that call runtime/cone.h's per-sample functions directly (the descent, a segment's light,
// a shadow cone).
#pragma once
#include <cstdint>
#include <vector>

#include "formats/canopy_file.h"
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

}  // namespace canopy::play::testing
