// render_cpu.cpp: the CPU reference backend: TBB over pixels, every array in host memory, the same
// renderPixel() (cone.h) as the CUDA kernel.
#include <algorithm>
#include <chrono>
#include <cstring>

#include "canopy/parallel.h"
#include "runtime/adaptive.h"
#include "runtime/backend.h"

namespace canopy::play {
namespace {

class CpuBackend final : public Backend {
 public:
  CpuBackend(const HostScene& scene, uint32_t slots)
      : pageBytes_(scene.pageBytes),
        pool_(size_t(slots) * scene.pageBytes),
        table_(scene.pageCount, -1),
        slotUsed_(slots, 0),
        pageWanted_(scene.pageCount, 0) {}

  std::string name() const override { return "cpu"; }
  unsigned char* stagingBuffers(uint32_t count) override {
    staging_.assign(size_t(count) * pageBytes_, 0);
    return staging_.data();
  }
  void upload(uint32_t slot, const unsigned char* staged) override {
    std::memcpy(pool_.data() + size_t(slot) * pageBytes_, staged, pageBytes_);
  }
  void setPageTable(const std::vector<int32_t>& table) override { table_ = table; }
  void waitUploads() override {}

  void renderRows(const HostScene& scene, const ShadeParams& shade, const CameraView& camera, uint32_t stamp, Band band, int eye,
                  float disparityScale) override {
    SceneView v = hostSceneView(scene);
    v.pageSlot = table_.data();
    v.pool = pool_.data();
    v.slotUsed = slotUsed_.data();
    v.pageWanted = pageWanted_.data();
    v.stamp = stamp;
    v.shade = shade;
    v.work = work_;
    if (shade.shadows == kShadowsMap) {
      // the extinction grid: once per scene (it depends on the instances and sigma only)
      const bool gridBuilt =
          extinction_.empty() || gridSigma_ != shade.sigma || gridCells_ != shade.shadowMapCells || gridCap_ != shade.shadowMapMaxVoxels;
      if (gridBuilt) {
        grid_ = planExtinctionGrid(scene, shade);
        extinction_.resize(size_t(grid_.dim[0]) * grid_.dim[1] * grid_.dim[2]);
        grid_.k = extinction_.data();
        const ExtinctionGridView g = grid_;
        parallelFor(int64_t(extinction_.size()), [&](int64_t i) { buildExtinctionVoxel(v, g, i); }, 256);
        gridSigma_ = shade.sigma, gridCells_ = shade.shadowMapCells, gridCap_ = shade.shadowMapMaxVoxels;
      }
      int sub = 1;
      v.shadowMap = planShadowMap(scene, shade, grid_, sub);
      const int64_t columns = int64_t(v.shadowMap.dim[0]) * v.shadowMap.dim[1];
      shadowMap_.resize(size_t(columns) * v.shadowMap.dim[2]);
      v.shadowMap.T = shadowMap_.data();
      const ShadowMapView m = v.shadowMap;
      const ExtinctionGridView g = grid_;
      buildShadowMap(m, sub, gridBuilt, [&] {
        parallelFor(columns, [&](int64_t c) { buildShadowMapColumn(m, g, sub, c); }, 16);
        if (work_) work_->shadowMapSteps += uint64_t(columns) * uint64_t(m.dim[2]) * uint64_t(sub);
      });
    }
    if (shade.farStart >= 0.0f && farFieldReachable(scene, shade, camera)) {
      // the far field: once per scene (it depends on the instances and sigma only), once a cone can reach it
      if (farValues_.empty() || farSigma_ != shade.sigma) {
        far_ = scene.far;
        farValues_.assign(size_t(far_.dim[0]) * far_.dim[1] * far_.dim[2] * kFarFieldChannels, 0.0f);
        far_.values = farValues_.data();
        const FarFieldView f = far_;
        parallelFor(int64_t(f.dim[0]) * f.dim[1] * f.dim[2], [&](int64_t i) { buildFarFieldVoxel(v, f, i); }, 256);
        farSigma_ = shade.sigma;
      }
      v.far = far_;
    }
    lastShadowMap_ = v.shadowMap;
    view_ = v;
    const size_t pixels = size_t(camera.width) * camera.height;
    std::vector<float>& image = image_[eye];
    if (image.size() != pixels * 4) image.assign(pixels * 4, 0.0f);
    float* out = image.data();
    float* depth = nullptr;
    if (disparityScale > 0.0f) {
      if (disparity_.size() != pixels * kStereoPixelFloats) disparity_.assign(pixels * kStereoPixelFloats, 0.0f);
      depth = disparity_.data();
      disparityScale_ = disparityScale;
    }
    lastFilled_ = 0;
    if (adaptive_ > 0.0f && !depth && eye == 0) return renderAdaptive(v, camera, band, out);
    const int64_t first = int64_t(band.y0) * camera.width;
    parallelFor(int64_t(band.rows()) * camera.width, [&](int64_t i) { renderPixel(v, camera, first + i, out, depth, disparityScale); }, 64);
  }
  // adaptive.h: the lattice; each block of the band tested; the passing blocks' off-lattice pixels
  // filled, the failing blocks' traced.
  void renderAdaptive(const SceneView& v, const CameraView& camera, Band band, float* out) {
    int r0, r1;  // the rows of the band's blocks, whose lattice the blocks' tests read
    adaptiveBlockRows(band.y0, band.y1, tileH_, camera.height, r0, r1);
    const int w = camera.width, h = camera.height, lw = adaptiveLatticeWidth(w), ly0 = adaptiveLatticeFirst(r0);
    const int64_t lattice = int64_t(lw) * (adaptiveLatticeEnd(r1, h) - ly0);
    parallelFor(lattice, [&](int64_t i) {
      const int x = 2 * int(i % lw), y = 2 * (ly0 + int(i / lw));
      renderPixel(v, camera, int64_t(y) * w + x, out, nullptr, 0.0f);
    }, 64);
    const int blocksX = (w + tileW_ - 1) / tileW_, by0 = adaptiveBlockRowFirst(band.y0, tileH_);
    const int64_t blocks = int64_t(blocksX) * (adaptiveBlockRowEnd(band.y1, tileH_) - by0);
    blockPass_.assign(size_t(blocks), 0);
    parallelFor(blocks, [&](int64_t b) {
      blockPass_[size_t(b)] = adaptiveBlockAgrees(out, w, h, int(b % blocksX), by0 + int(b / blocksX), tileW_, tileH_, adaptive_) ? 1 : 0;
    }, 64);
    trace_.clear();
    const int64_t positions = int64_t(blocksX) * ((band.rows() + tileH_ - 1) / tileH_) * tileW_ * tileH_;  // the band's warp tiles
    for (int64_t j = 0; j < positions; ++j) {
      int x, y;
      const int a = adaptiveAction(j, blocksX, tileW_, tileH_, w, band.y0, band.y1, by0, blockPass_.data(), x, y);
      if (a == kAdaptiveFill) adaptiveFillPixel(out, w, x, y);
      if (a == kAdaptiveTrace) trace_.push_back(int64_t(y) * w + x);
    }
    parallelFor(int64_t(trace_.size()), [&](int64_t k) { renderPixel(v, camera, trace_[size_t(k)], out, nullptr, 0.0f); }, 64);
    lastFilled_ = adaptiveOffLattice(w, band.y0, band.y1) - trace_.size();
  }
  StereoCounts reprojectRows(const HostScene& scene, const CameraView& right, uint32_t stamp, Band band, const StereoParams& p) override {
    (void)scene, (void)stamp;  // the stamp and scene of view_, the last render of this pass
    const auto t0 = std::chrono::steady_clock::now();
    const size_t pixels = size_t(right.width) * right.height;
    if (keys_.size() != pixels) keys_.resize(pixels), behind_.resize(pixels), cover_.resize(pixels), holeFrom_.resize(pixels);
    if (image_[1].size() != pixels * 4) image_[1].assign(pixels * 4, 0.0f);
    const StereoView sv =
        stereoView(image_[0].data(), disparity_.data(), keys_.data(), behind_.data(), cover_.data(), image_[1].data(), right.width, p);
    // one row per task: a row's spans land in the row (max and count, in any order: the same keys)
    std::vector<uint8_t> hole(size_t(band.rows()) * right.width);
    parallelFor(band.rows(), [&](int64_t r) {
      const int y = band.y0 + int(r);
      const int64_t row = int64_t(y) * right.width;
      std::fill(keys_.begin() + row, keys_.begin() + row + right.width, 0ull);
      std::fill(behind_.begin() + row, behind_.begin() + row + right.width, 0ull);
      std::fill(cover_.begin() + row, cover_.begin() + row + right.width, 0u);
      for (int x = 0; x < right.width; ++x)
        stereoSplatNearest(sv, x, y, [&](int64_t i, unsigned long long key, bool counts) {
          keys_[size_t(i)] = std::max(keys_[size_t(i)], key);
          cover_[size_t(i)] += counts ? 1u : 0u;
        });
      for (int x = 0; x < right.width; ++x)
        stereoSplatBehind(sv, x, y, [&](int64_t i, unsigned long long key) { behind_[size_t(i)] = std::max(behind_[size_t(i)], key); });
      for (int x = 0; x < right.width; ++x) hole[size_t(r) * right.width + x] = stereoResolveHole(sv, x, y, holeFrom_.data() + row + x) ? 0 : 1;
    }, 1);
    std::vector<int64_t> holes;
    uint64_t behind = 0;
    for (size_t k = 0; k < hole.size(); ++k)
      if (hole[k]) {
        holes.push_back(int64_t(band.y0) * right.width + int64_t(k));
        behind += holeFrom_[size_t(holes.back())] > 0.0f ? 1u : 0u;
      }
    const double reprojectS = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    const SceneView v = view_;
    float* out = image_[1].data();
    float* from = holeFrom_.data();
    parallelFor(int64_t(holes.size()), [&](int64_t k) { renderPixel(v, right, holes[size_t(k)], out, nullptr, disparityScale_, from); }, 64);
    return StereoCounts{holes.size(), behind, reprojectS};
  }
  void readStamps(std::vector<uint32_t>& slotUsed, std::vector<uint32_t>& pageWanted) override {
    slotUsed = slotUsed_;
    pageWanted = pageWanted_;
  }
  void readRows(std::vector<float>& rgba, int eye, Band band, int width) override {
    const size_t first = size_t(band.y0) * width * 4, count = size_t(band.rows()) * width * 4;
    std::copy(image_[eye].begin() + first, image_[eye].begin() + first + count, rgba.begin() + first);
  }
  void countWork(WorkCounters* work) override { work_ = work; }

 private:
  uint32_t pageBytes_;
  std::vector<unsigned char> pool_, staging_;
  std::vector<int32_t> table_;
  std::vector<uint32_t> slotUsed_, pageWanted_;
  std::vector<float> image_[2], disparity_, shadowMap_, extinction_, farValues_;
  std::vector<float> holeFrom_;  // stereo: per right-eye hole, where its trace starts (stereoResolveHole)
  std::vector<uint8_t> blockPass_;  // adaptive sampling: the band's blocks, 1 where filled
  std::vector<int64_t> trace_;      // and the off-lattice pixels of the others, to trace
  float disparityScale_ = 0.0f;  // the traced eye's (renderRows)
  std::vector<unsigned long long> keys_, behind_;
  std::vector<uint32_t> cover_;
  SceneView view_{};  // the last render's view (its stamp, shade and shadow map): the second eye's holes use it
  ExtinctionGridView grid_{};
  float gridSigma_ = -1.0f, gridCells_ = -1.0f;
  uint32_t gridCap_ = 0;
  FarFieldView far_{};
  float farSigma_ = -1.0f;
  WorkCounters* work_ = nullptr;
};

}  // namespace

std::unique_ptr<Backend> makeCpuBackend(const HostScene& scene, uint32_t slots) {
  return std::make_unique<CpuBackend>(scene, slots);
}

}  // namespace canopy::play
