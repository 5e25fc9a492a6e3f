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
    image_.assign(size_t(camera.width) * camera.height * 4, 0.0f);
    float* out = image_.data();
    parallelFor(int64_t(camera.width) * camera.height, [&](int64_t i) { renderPixel(v, camera, i, out); }, 64);
  }
  void readStamps(std::vector<uint32_t>& slotUsed, std::vector<uint32_t>& pageWanted) override {
    slotUsed = slotUsed_;
    pageWanted = pageWanted_;
  }
  void readImage(std::vector<float>& rgba) override { rgba = image_; }

 private:
  uint32_t pageBytes_;
  std::vector<unsigned char> pool_, staging_;
  std::vector<int32_t> table_;
  std::vector<uint32_t> slotUsed_, pageWanted_;
  std::vector<float> image_;
};

}  // namespace

std::unique_ptr<Backend> makeCpuBackend(const HostScene& scene, uint32_t slots) {
  return std::make_unique<CpuBackend>(scene, slots);
}

}  // namespace canopy::play
