// fuzz_canopy.cpp: libFuzzer harness for the .canopy reader. Any input must either be rejected
// with a canopy::Error or be read in full (every page, a descent and a brick sample per model, its
// light item and its Haar light, every scene light base) without a sanitizer report.
#include <cstddef>
#include <cstdint>
#include <vector>

#include "canopy/errors.h"
#include "formats/canopy_file.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  try {
    canopy::CanopyFile f = canopy::CanopyFile::fromMemory(data, size, "fuzz.canopy");
    std::vector<unsigned char> page(f.header().pageBytes);
    for (uint32_t i = 0; i < f.pageCount() && i < 64; ++i) {
      try {
        f.readPage(i, page.data());
      } catch (const canopy::Error&) {
      }
    }
    if (f.hasSceneLight()) {  // every base of the scene light (B00, and B01..B18 in a 1.2 file)
      const size_t nodes = size_t(f.sceneLight().dim[0]) * size_t(f.sceneLight().dim[1]) * size_t(f.sceneLight().dim[2]);
      if (f.sceneLightValues().size() != nodes * f.sceneLightBases()) __builtin_trap();
      volatile float sum = 0.0f;
      for (float v : f.sceneLightValues()) sum = sum + v;
    }
    for (uint32_t m = 0; m < f.modelCount(); ++m) {
      const canopy::CanopyModel& M = f.model(m);
      for (int k = 0; k < 8; ++k) {
        const float u = (float(k) + 0.5f) / 8.0f;
        const canopy::CanopyLookup r = f.descend(m, u, 1.0f - u, u * u, M.depth);
        if (r.node.brick == canopy::kCanopyNone) continue;
        const canopy::CanopyFile::BrickLocation at = f.brickLocation(m, r.node.brick);  // dense or (2.0) sparse
        try {
          f.readPage(at.page, page.data());
        } catch (const canopy::Error&) {
          continue;
        }
        volatile float d = canopy::canopySampleBrickInPage(page.data(), at.slot, at.sparse, r.local[0], r.local[1], r.local[2]).density;
        (void)d;
        if (M.flags & canopy::kCanopyModelHaarLight) {  // the finest level's Haar light at the sample's lattice point
          const canopy::CanopyHaarView hv = f.haarView(m);
          const canopy::CanopyHaarLocation at = canopy::canopyHaarLocate(hv, float(M.latticeMin[0]) + 7.3f * u, float(M.latticeMin[1]) + 3.1f * u,
                                                                         float(M.latticeMin[2]) + 5.7f * u);
          if (at.page != canopy::kCanopyNone) {
            std::vector<unsigned char> hp(f.header().pageBytes);
            try {
              f.readPage(at.page, hp.data());
              const canopy::haar::Rgb v = canopy::canopyHaarSampleAt(canopy::canopyHaarItemInPage(hp.data(), at.item), hv.fp16,
                                                                     uint32_t(k) % canopy::kCanopyLightBases, at.at);
              volatile float l = v.r + v.g + v.b;
              (void)l;
            } catch (const canopy::Error&) {
            }
          }
        }
        if (r.node.brick >= M.lightCount) continue;  // light items: every brick, or those above the detail levels
        const uint32_t lpp = f.header().lightItemsPerPage;
        try {
          f.readPage(canopy::canopyLightPage(M, r.node.brick, lpp), page.data());
        } catch (const canopy::Error&) {
          continue;
        }
        canopy::canopyPreparePage(page.data(), f.header());  // float16 items of a file before 4.0 converted
        float rgb[3];
        canopy::canopySampleLight(canopy::canopyLightInPage(page.data(), r.node.brick % lpp), uint32_t(k) % canopy::kCanopyLightBases,
                                  r.local[0], r.local[1], r.local[2], rgb);
        volatile float l = rgb[0] + rgb[1] + rgb[2];
        (void)l;
      }
    }
  } catch (const canopy::Error&) {
  }
  return 0;
}
