// render_cpu.cpp: the CPU reference backend: TBB over pixels, every array in host memory, the same
// renderPixel() (cone.h) as the CUDA kernel.
#include <cstring>

#include "canopy/parallel.h"
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

  void render(const HostScene& scene, const ShadeParams& shade, const CameraView& camera, uint32_t stamp) override {
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
      if (extinction_.empty() || gridSigma_ != shade.sigma || gridCells_ != shade.shadowMapCells || gridCap_ != shade.shadowMapMaxVoxels) {
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
      parallelFor(columns, [&](int64_t c) { buildShadowMapColumn(m, g, sub, c); }, 16);
      if (work_) work_->shadowMapSteps += uint64_t(columns) * uint64_t(m.dim[2]) * uint64_t(sub);
    }
    lastShadowMap_ = v.shadowMap;
    image_.assign(size_t(camera.width) * camera.height * 4, 0.0f);
    float* out = image_.data();
    parallelFor(int64_t(camera.width) * camera.height, [&](int64_t i) { renderPixel(v, camera, i, out); }, 64);
  }
  void readStamps(std::vector<uint32_t>& slotUsed, std::vector<uint32_t>& pageWanted) override {
    slotUsed = slotUsed_;
    pageWanted = pageWanted_;
  }
  void readImage(std::vector<float>& rgba) override { rgba = image_; }
  void countWork(WorkCounters* work) override { work_ = work; }

 private:
  uint32_t pageBytes_;
  std::vector<unsigned char> pool_, staging_;
  std::vector<int32_t> table_;
  std::vector<uint32_t> slotUsed_, pageWanted_;
  std::vector<float> image_, shadowMap_, extinction_;
  ExtinctionGridView grid_{};
  float gridSigma_ = -1.0f, gridCells_ = -1.0f;
  uint32_t gridCap_ = 0;
  WorkCounters* work_ = nullptr;
};

}  // namespace

std::unique_ptr<Backend> makeCpuBackend(const HostScene& scene, uint32_t slots) {
  return std::make_unique<CpuBackend>(scene, slots);
}

}  // namespace canopy::play
