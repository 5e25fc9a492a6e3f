// render_cuda.cu: the CUDA backend: the same renderPixel() (cone.h) as the CPU reference, one thread
// per pixel, with the node tiles resident on the device and the brick and light pages in one device
// pool (one page table: a light page is a page like any other, see cone.h 7).
//
// Uploads: the loader reads pages into pinned staging buffers; upload() copies a page into its slot
// on the copy stream, setPageTable() copies the table after them on the same stream and records an
// event that the compute stream waits on before the next kernel. A kernel therefore never sees a
// table entry whose page is still in flight, and never waits for the disk; the host does not wait
// for the copies either (they overlap the host's work until the kernel launch).
#include <cstring>

#include "canopy/parallel_cuda.cuh"
#include "runtime/backend.h"

namespace canopy::play {
namespace {

// One thread per pixel, a warp on a tileW x tileH tile of pixels (default 8x4 rather than 32
// pixels of one row: the rays of a warp stay closer together, so they walk the same instances and
// nodes longer). Thread j -> tile j / (tileW tileH), lane j % (tileW tileH). One kernel per shadow
// path (renderPixelT): the map's and no-shadow kernel has no shadow-cone code.
template <bool kWithCones, bool kWithLight>
struct PixelKernel {
  SceneView scene;
  CameraView camera;
  float* out;
  int tilesX, tileW, tileH;
  __device__ void operator()(int64_t j) const {
    const int64_t tile = j / (tileW * tileH);
    const int lane = int(j % (tileW * tileH));
    const int x = int(tile % tilesX) * tileW + lane % tileW;
    const int y = int(tile / tilesX) * tileH + lane / tileW;
    if (x >= camera.width || y >= camera.height) return;
    renderPixelT<kWithCones, kWithLight>(scene, camera, int64_t(y) * camera.width + x, out);
  }
};

// The pixel kernel: 128 threads per block; kMinBlocks > 0 asks ptxas for at least that many
// resident blocks per SM (__launch_bounds__: fewer registers, maybe spills), 0 leaves it free.
// Map kernels by default: 6 blocks for scenes without LB light, unconstrained with it (ptxas -v,
// sm_90, with the empty-cell skip: 91 registers and a 2608-byte stack free, 56 bytes of spill
// stores at 6 blocks; 134 registers with light). Measured on an H200 before the skip, when a step
// stopped keeping a per-hit segment array (docs/performance.md, 'Occupancy'; 87 registers then,
// 12 bytes of spills at 6): 6 blocks took the forest orbit 43.19 -> 42.49 ms and the walk 15.41 -> 14.84 ms,
// the grove (lit) 14.44 -> 14.90 ms; 8 blocks was slower on all three. setPixelOccupancy overrides
// it (6, 8, or -1 for unconstrained). Shadow-cone kernel: 5 (96 registers, as before the light change).
constexpr int kPixelBlock = 128;
template <bool kWithCones, bool kWithLight, int kMinBlocks>
__global__ void __launch_bounds__(kPixelBlock, kMinBlocks > 0 ? kMinBlocks : 1) pixelKernel(PixelKernel<kWithCones, kWithLight> k, int64_t n) {
  const int64_t i = blockIdx.x * int64_t(kPixelBlock) + threadIdx.x;
  if (i < n) k(i);
}

template <bool kWithCones, bool kWithLight, int kMinBlocks>
void launchPixels(const PixelKernel<kWithCones, kWithLight>& k, int64_t n, cudaStream_t stream) {
  if (n <= 0) return;
  pixelKernel<kWithCones, kWithLight, kMinBlocks><<<unsigned((n + kPixelBlock - 1) / kPixelBlock), kPixelBlock, 0, stream>>>(k, n);
  CANOPY_CUDA_CHECK(cudaGetLastError());
}

struct ExtinctionKernel {
  SceneView scene;
  ExtinctionGridView grid;
  __device__ void operator()(int64_t i) const { buildExtinctionVoxel(scene, grid, i); }
};

struct ShadowMapKernel {
  ShadowMapView map;
  ExtinctionGridView grid;
  int sub;
  __device__ void operator()(int64_t c) const { buildShadowMapColumn(map, grid, sub, c); }
};

template <class T>
void uploadVector(cuda::DeviceBuffer<T>& d, const std::vector<T>& h) {
  d.resize(h.empty() ? 1 : h.size());
  if (!h.empty()) d.upload(h.data(), h.size());
}

class CudaBackend final : public Backend {
 public:
  CudaBackend(const HostScene& scene, uint32_t slots, int device) : pageBytes_(scene.pageBytes), pageCount_(scene.pageCount) {
    CANOPY_CUDA_CHECK(cudaSetDevice(device));
    CANOPY_CUDA_CHECK(cudaStreamCreateWithFlags(&compute_, cudaStreamNonBlocking));
    CANOPY_CUDA_CHECK(cudaStreamCreateWithFlags(&copy_, cudaStreamNonBlocking));
    for (int i = 0; i < 2; ++i) CANOPY_CUDA_CHECK(cudaEventCreateWithFlags(&tableCopied_[i], cudaEventDisableTiming));
    // node tiles: every model's, resident (they are the cache's page table of bricks)
    size_t tiles = 0;
    for (size_t m = 0; m < scene.models.size(); ++m) tiles = std::max(tiles, size_t(scene.modelFirstTile[m] + scene.models[m].tileCount) * 8);
    std::vector<CanopyNode> allTiles(tiles > 0 ? tiles : 1);
    for (size_t m = 0; m < scene.models.size(); ++m)
      std::memcpy(allTiles.data() + size_t(scene.modelFirstTile[m]) * 8, scene.models[m].tiles, size_t(scene.models[m].tileCount) * 8 * sizeof(CanopyNode));
    uploadVector(tiles_, allTiles);
    if (scene.haarIndex) uploadVector(haarIndex_, *scene.haarIndex);
    std::vector<ModelView> models = scene.models;
    for (size_t m = 0; m < models.size(); ++m) {
      models[m].tiles = tiles_.data() + size_t(scene.modelFirstTile[m]) * 8;
      if (models[m].haarLight) models[m].haar.index = haarIndex_.data() + scene.modelFirstHaarIndex[m];
    }
    uploadVector(models_, models);
    uploadVector(gridStart_, scene.gridStart);
    uploadVector(gridItems_, scene.gridItems);
    uploadVector(gridFaceStart_, scene.gridFaceStart);
    uploadVector(gridFaceItems_, scene.gridFaceItems);
    uploadVector(light_, scene.lightPairs);
    lightVersion_ = scene.lightVersion;
    instances_.resize(std::max<size_t>(scene.instances.size(), 1));
    pool_.resize(std::max<size_t>(size_t(slots) * pageBytes_, 1));
    table_.resize(std::max<uint32_t>(pageCount_, 1));
    slotUsed_.resize(std::max<uint32_t>(slots, 1));
    pageWanted_.resize(std::max<uint32_t>(pageCount_, 1));
    CANOPY_CUDA_CHECK(cudaMemset(table_.data(), 0xFF, table_.size() * sizeof(int32_t)));  // -1: missing
    CANOPY_CUDA_CHECK(cudaMemset(slotUsed_.data(), 0, slotUsed_.size() * sizeof(uint32_t)));
    CANOPY_CUDA_CHECK(cudaMemset(pageWanted_.data(), 0, pageWanted_.size() * sizeof(uint32_t)));
    for (int i = 0; i < 2; ++i) CANOPY_CUDA_CHECK(cudaMallocHost(&tableHost_[i], table_.size() * sizeof(int32_t)));
    slots_ = slots;
    // the memsets and uploads above ran on the legacy default stream, which the non-blocking
    // compute and copy streams do not wait for
    CANOPY_CUDA_CHECK(cudaDeviceSynchronize());
  }
  ~CudaBackend() override {
    cudaStreamSynchronize(copy_);
    cudaStreamSynchronize(compute_);
    if (staging_) cudaFreeHost(staging_);
    for (int i = 0; i < 2; ++i) {
      if (tableHost_[i]) cudaFreeHost(tableHost_[i]);
      cudaEventDestroy(tableCopied_[i]);
    }
    cudaStreamDestroy(copy_);
    cudaStreamDestroy(compute_);
  }

  std::string name() const override { return "cuda"; }
  unsigned char* stagingBuffers(uint32_t count) override {
    if (staging_) cudaFreeHost(staging_);
    CANOPY_CUDA_CHECK(cudaMallocHost(reinterpret_cast<void**>(&staging_), size_t(count) * pageBytes_));
    return staging_;
  }
  void upload(uint32_t slot, const unsigned char* staged) override {
    CANOPY_CUDA_CHECK(cudaMemcpyAsync(pool_.data() + size_t(slot) * pageBytes_, staged, pageBytes_, cudaMemcpyHostToDevice, copy_));
  }
  void setPageTable(const std::vector<int32_t>& table) override {
    // two pinned mirrors, alternating: the one rewritten now was copied two calls ago, a copy that
    // a finished kernel has already waited for, so this never waits for the page uploads
    mirror_ ^= 1;
    CANOPY_CUDA_CHECK(cudaEventSynchronize(tableCopied_[mirror_]));
    std::memcpy(tableHost_[mirror_], table.data(), table.size() * sizeof(int32_t));
    CANOPY_CUDA_CHECK(cudaMemcpyAsync(table_.data(), tableHost_[mirror_], table.size() * sizeof(int32_t), cudaMemcpyHostToDevice, copy_));
    CANOPY_CUDA_CHECK(cudaEventRecord(tableCopied_[mirror_], copy_));
    CANOPY_CUDA_CHECK(cudaStreamWaitEvent(compute_, tableCopied_[mirror_], 0));
  }
  void waitUploads() override { CANOPY_CUDA_CHECK(cudaStreamSynchronize(copy_)); }

  void render(const HostScene& scene, const ShadeParams& shade, const CameraView& camera, uint32_t stamp) override {
    if (!scene.instances.empty())
      CANOPY_CUDA_CHECK(cudaMemcpyAsync(instances_.data(), scene.instances.data(), scene.instances.size() * sizeof(InstanceView),
                                        cudaMemcpyHostToDevice, compute_));
    // The scene light's factor pairs change with the sun (HostScene::setSun): a few thousand nodes,
    // copied before this frame's kernels on the same stream (the last frame's kernels have finished:
    // render() ends with a synchronisation).
    if (scene.lightVersion != lightVersion_ && !scene.lightPairs.empty()) {
      if (light_.size() != scene.lightPairs.size()) light_.resize(scene.lightPairs.size());
      CANOPY_CUDA_CHECK(cudaMemcpyAsync(light_.data(), scene.lightPairs.data(), scene.lightPairs.size() * sizeof(SceneLightPair),
                                        cudaMemcpyHostToDevice, compute_));
      lightVersion_ = scene.lightVersion;
    }
    const size_t pixels = size_t(camera.width) * camera.height;
    if (image_.size() != pixels * 4) image_.resize(pixels * 4);
    SceneView v = hostSceneView(scene);
    v.models = models_.data();
    v.instances = instances_.data();
    v.gridStart = gridStart_.data();
    v.gridItems = gridItems_.data();
    v.gridFaceStart = gridFaceStart_.data();
    v.gridFaceItems = gridFaceItems_.data();
    v.light.values = scene.hasSceneLight ? light_.data() : nullptr;
    v.pageSlot = table_.data();
    v.pool = pool_.data();
    v.slotUsed = slotUsed_.data();
    v.pageWanted = pageWanted_.data();
    v.stamp = stamp;
    v.shade = shade;
    if (shade.shadows == kShadowsMap) {
      // the extinction grid: once per scene (it depends on the instances and sigma only)
      if (extinction_.size() == 0 || gridSigma_ != shade.sigma || gridCells_ != shade.shadowMapCells || gridCap_ != shade.shadowMapMaxVoxels) {
        grid_ = planExtinctionGrid(scene, shade);
        const size_t n = size_t(grid_.dim[0]) * grid_.dim[1] * grid_.dim[2];
        CANOPY_CUDA_CHECK(cudaStreamSynchronize(compute_));
        extinction_.resize(n);
        grid_.k = extinction_.data();
        cuda::parallelFor(int64_t(n), ExtinctionKernel{v, grid_}, compute_, 128);
        gridSigma_ = shade.sigma, gridCells_ = shade.shadowMapCells, gridCap_ = shade.shadowMapMaxVoxels;
      }
      int sub = 1;
      v.shadowMap = planShadowMap(scene, shade, grid_, sub);
      const int64_t columns = int64_t(v.shadowMap.dim[0]) * v.shadowMap.dim[1];
      const size_t n = size_t(columns) * v.shadowMap.dim[2];
      if (shadowMap_.size() < n) {
        CANOPY_CUDA_CHECK(cudaStreamSynchronize(compute_));
        shadowMap_.resize(n + n / 4);  // room for the next frames' slightly larger boxes
      }
      v.shadowMap.T = shadowMap_.data();
      cuda::parallelFor(columns, ShadowMapKernel{v.shadowMap, grid_, sub}, compute_, 128);
    }
    lastShadowMap_ = v.shadowMap;
    const int tilesX = (camera.width + tileW_ - 1) / tileW_, tilesY = (camera.height + tileH_ - 1) / tileH_;
    const int64_t threads = int64_t(tilesX) * tilesY * tileW_ * tileH_;
    // one kernel per shadow path and per light (renderPixelT): the map's kernel for a scene
    // without lit models has neither shadow-cone nor LB light code
    if (shade.shadows == kShadowsCone) {
      launchPixels<true, true, 5>(PixelKernel<true, true>{v, camera, image_.data(), tilesX, tileW_, tileH_}, threads, compute_);
    } else if (scene.litModels > 0) {
      launchMap(PixelKernel<false, true>{v, camera, image_.data(), tilesX, tileW_, tileH_}, threads);
    } else {
      launchMap(PixelKernel<false, false>{v, camera, image_.data(), tilesX, tileW_, tileH_}, threads);
    }
    CANOPY_CUDA_CHECK(cudaStreamSynchronize(compute_));
  }
  template <bool kWithLight>
  void launchMap(const PixelKernel<false, kWithLight>& k, int64_t threads) {
    const int blocks = minBlocks_ != 0 ? minBlocks_ : (kWithLight ? -1 : 6);
    if (blocks >= 8)
      launchPixels<false, kWithLight, 8>(k, threads, compute_);
    else if (blocks >= 6)
      launchPixels<false, kWithLight, 6>(k, threads, compute_);
    else
      launchPixels<false, kWithLight, 0>(k, threads, compute_);
  }
  void readStamps(std::vector<uint32_t>& slotUsed, std::vector<uint32_t>& pageWanted) override {
    slotUsed.resize(slots_);
    pageWanted.resize(pageCount_);
    if (slots_) slotUsed_.download(slotUsed.data(), slots_);
    if (pageCount_) pageWanted_.download(pageWanted.data(), pageCount_);
  }
  void setPixelTile(int w, int h) override { tileW_ = w, tileH_ = h; }
  void setPixelOccupancy(int minBlocks) override { minBlocks_ = minBlocks; }
  void readImage(std::vector<float>& rgba) override {
    rgba.resize(image_.size());
    image_.download(rgba.data(), image_.size());
  }

 private:
  uint32_t pageBytes_, pageCount_, slots_ = 0;
  int tileW_ = 8, tileH_ = 4;
  int minBlocks_ = 0;
  cudaStream_t compute_ = nullptr, copy_ = nullptr;
  cudaEvent_t tableCopied_[2] = {nullptr, nullptr};
  int mirror_ = 0;
  cuda::DeviceBuffer<CanopyNode> tiles_;
  cuda::DeviceBuffer<uint32_t> haarIndex_;  // CanopyFile::haarIndex(): the Haar-lit models' group tables and locations
  cuda::DeviceBuffer<ModelView> models_;
  cuda::DeviceBuffer<InstanceView> instances_;
  cuda::DeviceBuffer<uint32_t> gridStart_, gridItems_, gridFaceStart_, gridFaceItems_;
  cuda::DeviceBuffer<SceneLightPair> light_;  // the scene light's factor pairs (HostScene::lightPairs)
  uint64_t lightVersion_ = 0;                  // the HostScene::lightVersion that light_ holds
  cuda::DeviceBuffer<unsigned char> pool_;
  cuda::DeviceBuffer<int32_t> table_;
  cuda::DeviceBuffer<uint32_t> slotUsed_, pageWanted_;
  cuda::DeviceBuffer<float> image_, shadowMap_, extinction_;
  ExtinctionGridView grid_{};
  float gridSigma_ = -1.0f, gridCells_ = -1.0f;
  uint32_t gridCap_ = 0;
  unsigned char* staging_ = nullptr;
  int32_t* tableHost_[2] = {nullptr, nullptr};
};

}  // namespace

std::unique_ptr<Backend> makeCudaBackend(const HostScene& scene, uint32_t slots, int deviceIndex) {
  return std::make_unique<CudaBackend>(scene, slots, deviceIndex < 0 ? 0 : deviceIndex);
}

}  // namespace canopy::play
