// sample_cuda.cu: see sample_cuda.h. No OpenVDB here.
#include "tests/octreepack/sample_cuda.h"

#include "canopy/parallel_cuda.cuh"

namespace canopy::octreepack::testing {
namespace {

struct SampleKernel {
  const CanopyNode* tiles;
  uint32_t tileCount;
  CanopyNode root;
  uint32_t depth, maxLevel, bricksPerPage, pageBytes;
  const unsigned char* pages;  // the model's brick pages, in order, pageBytes each
  const unsigned char* lightPages;  // its light pages (or null)
  uint32_t lightPerPage, lightBase;
  const float* points;
  CanopySample* out;
  float* lightOut;
  CANOPY_HD void operator()(int64_t i) const {
    const CanopyLookup r = canopyDescend(tiles, tileCount, root, depth, points[3 * i], points[3 * i + 1], points[3 * i + 2], maxLevel);
    if (r.node.brick == kCanopyNone) {
      out[i] = canopyUnpack(r.node.density, r.node.material);
      lightOut[3 * i] = lightOut[3 * i + 1] = lightOut[3 * i + 2] = 0.0f;
      return;
    }
    if (lightPages) {
      const unsigned char* lp = lightPages + size_t(r.node.brick / lightPerPage) * pageBytes;
      canopySampleLight(canopyLightInPage(lp, r.node.brick % lightPerPage), lightBase, r.local[0], r.local[1], r.local[2], lightOut + 3 * i);
    } else {
      lightOut[3 * i] = lightOut[3 * i + 1] = lightOut[3 * i + 2] = 0.0f;
    }
    const unsigned char* page = pages + size_t(r.node.brick / bricksPerPage) * pageBytes;
    out[i] = canopySampleBrick(canopyBrickInPage(page, canopyBrickSlot(r.node.brick, bricksPerPage)), r.local[0], r.local[1], r.local[2]);
  }
};

}  // namespace

std::vector<CanopySample> sampleOnCuda(const CanopyFile& f, uint32_t model, const std::vector<float>& points, uint32_t maxLevel,
                                       std::vector<float>* lightRgb, uint32_t lightBase) {
  const CanopyModel& M = f.model(model);
  const uint32_t pageBytes = f.header().pageBytes;
  std::vector<unsigned char> pages(size_t(M.brickPageCount) * pageBytes);
  for (uint32_t p = 0; p < M.brickPageCount; ++p) f.readPage(M.firstBrickPage + p, pages.data() + size_t(p) * pageBytes);
  cuda::DeviceBuffer<CanopyNode> dTiles(size_t(M.tileCount) * 8 + 1);
  if (M.tileCount) dTiles.upload(f.tiles(model), size_t(M.tileCount) * 8);
  cuda::DeviceBuffer<unsigned char> dPages(pages.size() + 1);
  if (!pages.empty()) dPages.upload(pages.data(), pages.size());
  std::vector<unsigned char> lpages(size_t(M.lightPageCount) * pageBytes);
  for (uint32_t p = 0; p < M.lightPageCount; ++p) f.readPage(M.firstLightPage + p, lpages.data() + size_t(p) * pageBytes);
  cuda::DeviceBuffer<unsigned char> dLight(lpages.size() + 1);
  if (!lpages.empty()) dLight.upload(lpages.data(), lpages.size());
  cuda::DeviceBuffer<float> dPoints(points.size());
  dPoints.upload(points.data(), points.size());
  const size_t n = points.size() / 3;
  cuda::DeviceBuffer<CanopySample> dOut(n);
  cuda::DeviceBuffer<float> dLightOut(3 * n);
  SampleKernel k{dTiles.data(), M.tileCount, M.root, M.depth, maxLevel, f.header().bricksPerPage, pageBytes,
                 dPages.data(), lpages.empty() ? nullptr : dLight.data(), f.header().lightItemsPerPage, lightBase,
                 dPoints.data(), dOut.data(), dLightOut.data()};
  cuda::parallelFor(int64_t(n), k);
  CANOPY_CUDA_CHECK(cudaDeviceSynchronize());
  std::vector<CanopySample> out(n);
  dOut.download(out.data(), n);
  if (lightRgb) {
    lightRgb->resize(3 * n);
    dLightOut.download(lightRgb->data(), 3 * n);
  }
  return out;
}

}  // namespace canopy::octreepack::testing
