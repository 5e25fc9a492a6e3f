// render_cuda.cu: the CUDA backend: the same renderPixel() (cone.h) as the CPU reference, one thread
// per pixel, with the node tiles resident on the device and the brick and light pages in one device
// pool (one page table: a light page is a page like any other, see cone.h 7).
//
// Uploads: the loader reads pages into pinned staging buffers; upload() copies a page into its slot
// on the copy stream, setPageTable() copies the table after them on the same stream and records an
// event that the compute stream waits on before the next kernel. A kernel therefore never sees a
// table entry whose page is still in flight, and never waits for the disk; the host does not wait
// for the copies either (they overlap the host's work until the kernel launch).
#include <chrono>
#include <cstring>

#include <cub/device/device_select.cuh>

#include "canopy/parallel_cuda.cuh"
#include "runtime/adaptive.h"
#include "runtime/backend.h"

namespace canopy::play {
namespace {

// One thread per pixel, a warp on a tileW x tileH tile of pixels (default 4x8 rather than 32
// pixels of one row: the rays of a warp stay closer together, so they walk the same instances and
// nodes longer; 4x8 rather than 8x4: 0.97-0.98x the time on the real forest, one H100,
// 2026-12-06). Thread j -> tile j / (tileW tileH), lane j % (tileW tileH). One kernel per shadow
// path (renderPixelT): the map's and no-shadow kernel has no shadow-cone code, and only the optional
// paths the frame uses (kPaths: scenePaths, or stereo's three sets, stereoPaths).
template <bool kWithCones, bool kWithLight, bool kWithDepth = false, bool kBehind = false, uint32_t kPaths = kAllPaths>
struct PixelKernel {
  SceneView scene;
  CameraView camera;
  float* out;
  int tilesX, tileW, tileH;
  int y0, y1;                // the band's rows [y0, y1) (tiles.h)
  const int32_t* list;       // nullptr: thread j renders tile position j; else list[j] (stereo's holes)
  float* stereo;             // renderPixelT's: kWithDepth, the layers per pixel (stereo's traced eye); kBehind, where
                             // each hole's trace starts (stereo's holes)
  float disparityScale;
  bool lattice;              // adaptive sampling's first pass: position k of the band's lattice (adaptive.h; tilesX its)
  __device__ void operator()(int64_t k) const {
    int x, y;
    if (lattice ? !adaptiveLatticePixel(k, tilesX, tileW, tileH, camera.width, y0, y1, camera.height, x, y)
                : !bandTilePixel(list ? int64_t(list[k]) : k, tilesX, tileW, tileH, camera.width, y0, y1, x, y))
      return;
    renderPixelT<kWithCones, kWithLight, kWithDepth, kBehind, kPaths>(scene, camera, int64_t(y) * camera.width + x, out, stereo, disparityScale);
  }
};

// The pixel kernel: 128 threads per block; kMinBlocks > 0 asks ptxas for at least that many
// resident blocks per SM (__launch_bounds__: fewer registers, maybe spills), 0 leaves it free.
// Map kernels by default: 6 blocks for scenes without LB light, 5 with it (the unlit kernel, ptxas
// -v, sm_90, with the empty-cell skip: 91 registers and a 2608-byte stack free, 56 bytes of spill
// stores at 6 blocks). Measured on an H200 before the skip, when a step stopped keeping a per-hit segment array
// (docs/performance.md, 'Occupancy'; 87 registers then, 12 bytes of spills at 6): 6 blocks took the
// forest orbit 43.19 -> 42.49 ms and the walk 15.41 -> 14.84 ms, the grove (lit) 14.44 -> 14.90 ms;
// 8 blocks was slower on all three. The lit kernel since its light bases are rolled (cone_light.h
// lbBaseSum): 117 registers free (4 blocks), 96 and 64 bytes of spill stores at 5; on the real
// forest (one H100, 2026-12-06) 5 blocks took 0.98-0.99x the frame time at 4K, 0.99-1.01x at 1080p;
// 6 blocks (80 registers, 190 bytes of spill stores) 1.07-1.11x. setPixelOccupancy overrides
// it (6, 8, or -1 for unconstrained). Shadow-cone kernel: 5 (96 registers, as before the light change).
constexpr int kPixelBlock = 128;
template <bool kWithCones, bool kWithLight, bool kWithDepth, bool kBehind, uint32_t kPaths, int kMinBlocks>
__global__ void __launch_bounds__(kPixelBlock, kMinBlocks > 0 ? kMinBlocks : 1)
    pixelKernel(PixelKernel<kWithCones, kWithLight, kWithDepth, kBehind, kPaths> k, int64_t n) {
  const int64_t i = blockIdx.x * int64_t(kPixelBlock) + threadIdx.x;
  if (i < n) k(i);
}

template <int kMinBlocks, bool kWithCones, bool kWithLight, bool kWithDepth, bool kBehind, uint32_t kPaths>
void launchPixels(const PixelKernel<kWithCones, kWithLight, kWithDepth, kBehind, kPaths>& k, int64_t n, cudaStream_t stream) {
  if (n <= 0) return;
  pixelKernel<kWithCones, kWithLight, kWithDepth, kBehind, kPaths, kMinBlocks><<<unsigned((n + kPixelBlock - 1) / kPixelBlock), kPixelBlock, 0, stream>>>(k, n);
  CANOPY_CUDA_CHECK(cudaGetLastError());
}

// Stereo (stereo.h): the traced eye's spans into the right eye's keys and cover counts (one thread
// per traced pixel of the band), then each right-eye pixel resolved or marked a hole, and where its
// trace starts (stereoResolveHole; the holes traced behind a reprojected front counted in
// *behindCount, one atomic per warp). The marks: hole[half + j] = j for the tile position j of a
// hole of the half stereoHoleHalf gives it, -1 elsewhere; compacted in order (DeviceSelect), they
// are the list of pixels to trace, in tile order within a half, so a warp traces neighbouring holes.
struct StereoSplatKernel {
  StereoView view;
  int y0;
  __device__ void operator()(int64_t i) const {
    const int x = int(i % view.width), y = y0 + int(i / view.width);
    stereoSplatNearest(view, x, y, [&](int64_t r, unsigned long long key, bool counts) {
      atomicMax(view.keys + r, key);
      if (counts) atomicAdd(view.cover + r, 1u);
    });
  }
};

// Then, the keys complete, the spans behind each right-eye pixel's front span.
struct StereoBehindKernel {
  StereoView view;
  int y0;
  __device__ void operator()(int64_t i) const {
    const int x = int(i % view.width), y = y0 + int(i / view.width);
    stereoSplatBehind(view, x, y, [&](int64_t r, unsigned long long key) { atomicMax(view.behind + r, key); });
  }
};

struct StereoResolveKernel {
  StereoView view;
  int tilesX, tileW, tileH, y0, y1;
  int32_t* hole;
  int64_t half;  // the marks' halves: hole[0, half) and hole[half, 2 half)
  int order;     // kHoleOrder*
  float* from;
  unsigned long long* behindCount;
  __device__ void operator()(int64_t j) const {
    int x, y;
    const bool inBand = bandTilePixel(j, tilesX, tileW, tileH, view.width, y0, y1, x, y);
    bool isHole = false, isBehind = false;
    if (inBand) {
      float* f = from + (int64_t(y) * view.width + x);
      isHole = !stereoResolveHole(view, x, y, f);
      isBehind = isHole && *f > 0.0f;
    }
    const int h = stereoHoleHalf(order, isBehind);
    hole[j] = isHole && h == 0 ? int32_t(j) : -1;
    hole[half + j] = isHole && h == 1 ? int32_t(j) : -1;
    const unsigned active = __activemask();
    const unsigned behind = __ballot_sync(active, isBehind);
    if (behind != 0u && int(threadIdx.x & 31u) == __ffs(int(active)) - 1) atomicAdd(behindCount, static_cast<unsigned long long>(__popc(behind)));
  }
};

// Adaptive sampling (adaptive.h), after the lattice's trace: each block of the band tested (pass[b]
// = 1: filled), then per tile position j of the band its off-lattice pixel filled where its block
// passed, or marked (mark[j] = j; -1 elsewhere) where it failed; the marks are compacted in order
// as stereo's holes are, so that a warp traces the 24 off-lattice pixels of a failing 4x8 block and 8
// of the next failing one (where the band starts on a block row).
struct AdaptiveBlockKernel {
  const float* rgba;
  int width, height, tileW, tileH, blocksX, blockRow0;
  float tol;
  uint8_t* pass;
  __device__ void operator()(int64_t b) const {
    pass[b] = adaptiveBlockAgrees(rgba, width, height, int(b % blocksX), blockRow0 + int(b / blocksX), tileW, tileH, tol) ? 1 : 0;
  }
};

struct AdaptiveFillKernel {
  float* rgba;
  int width, tilesX, tileW, tileH, y0, y1, blockRow0;
  const uint8_t* pass;
  int32_t* mark;
  __device__ void operator()(int64_t j) const {
    int x, y;
    const int a = adaptiveAction(j, tilesX, tileW, tileH, width, y0, y1, blockRow0, pass, x, y);
    if (a == kAdaptiveFill) adaptiveFillPixel(rgba, width, x, y);
    mark[j] = a == kAdaptiveTrace ? int32_t(j) : -1;
  }
};

struct IsHole {
  __host__ __device__ bool operator()(int32_t j) const { return j >= 0; }
};

struct ExtinctionKernel {
  SceneView scene;
  ExtinctionGridView grid;
  __device__ void operator()(int64_t i) const { buildExtinctionVoxel(scene, grid, i); }
};

struct FarFieldKernel {
  SceneView scene;
  FarFieldView far;
  __device__ void operator()(int64_t i) const { buildFarFieldVoxel(scene, far, i); }
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
    device_ = device;
    CANOPY_CUDA_CHECK(cudaSetDevice(device));
    holeCount_.resize(1);
    behindCount_.resize(1);
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
    if (scene.sparseIndex) uploadVector(sparseIndex_, *scene.sparseIndex);
    std::vector<ModelView> models = scene.models;
    for (size_t m = 0; m < models.size(); ++m) {
      models[m].tiles = tiles_.data() + size_t(scene.modelFirstTile[m]) * 8;
      if (models[m].haarLight) models[m].haar.index = haarIndex_.data() + scene.modelFirstHaarIndex[m];
      if (models[m].sparseIndex) models[m].sparseIndex = sparseIndex_.data() + scene.modelFirstSparseIndex[m];
    }
    uploadVector(levelNodes_, scene.levelNodes);
    uploadVector(levelOf_, scene.levelOf);
    uploadVector(lightBricks_, scene.lightBricks);
    for (size_t m = 0; m < models.size() && m < scene.modelFirstLevelNode.size(); ++m) {  // none with --no-descent-table
      models[m].levelNodes = levelNodes_.data() + scene.modelFirstLevelNode[m];
      models[m].levelOf = levelOf_.data() + scene.modelFirstLevelNode[m];
      models[m].lightBricks = lightBricks_.data() + scene.modelFirstLevelNode[m];
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
    cudaSetDevice(device_);
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
    CANOPY_CUDA_CHECK(cudaSetDevice(device_));
    if (staging_) cudaFreeHost(staging_);
    CANOPY_CUDA_CHECK(cudaMallocHost(reinterpret_cast<void**>(&staging_), size_t(count) * pageBytes_));
    return staging_;
  }
  void upload(uint32_t slot, const unsigned char* staged) override {
    CANOPY_CUDA_CHECK(cudaSetDevice(device_));
    CANOPY_CUDA_CHECK(cudaMemcpyAsync(pool_.data() + size_t(slot) * pageBytes_, staged, pageBytes_, cudaMemcpyHostToDevice, copy_));
  }
  void setPageTable(const std::vector<int32_t>& table) override {
    CANOPY_CUDA_CHECK(cudaSetDevice(device_));
    // two pinned mirrors, alternating: the one rewritten now was copied two calls ago, a copy that
    // a finished kernel has already waited for, so this never waits for the page uploads
    mirror_ ^= 1;
    CANOPY_CUDA_CHECK(cudaEventSynchronize(tableCopied_[mirror_]));
    std::memcpy(tableHost_[mirror_], table.data(), table.size() * sizeof(int32_t));
    CANOPY_CUDA_CHECK(cudaMemcpyAsync(table_.data(), tableHost_[mirror_], table.size() * sizeof(int32_t), cudaMemcpyHostToDevice, copy_));
    CANOPY_CUDA_CHECK(cudaEventRecord(tableCopied_[mirror_], copy_));
    CANOPY_CUDA_CHECK(cudaStreamWaitEvent(compute_, tableCopied_[mirror_], 0));
  }
  void waitUploads() override {
    CANOPY_CUDA_CHECK(cudaSetDevice(device_));
    CANOPY_CUDA_CHECK(cudaStreamSynchronize(copy_));
  }

  void renderRows(const HostScene& scene, const ShadeParams& shade, const CameraView& camera, uint32_t stamp, Band band, int eye,
                  float disparityScale) override {
    CANOPY_CUDA_CHECK(cudaSetDevice(device_));  // the frame loop may call from any thread (one per band)
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
    if (image_[eye].size() != pixels * 4) image_[eye].resize(pixels * 4);
    float* depth = nullptr;
    if (disparityScale > 0.0f) {
      if (disparity_.size() != pixels * kStereoPixelFloats) disparity_.resize(pixels * kStereoPixelFloats);
      depth = disparity_.data();
      disparityScale_ = disparityScale;
    }
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
      const bool gridBuilt =
          extinction_.size() == 0 || gridSigma_ != shade.sigma || gridCells_ != shade.shadowMapCells || gridCap_ != shade.shadowMapMaxVoxels;
      if (gridBuilt) {
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
      buildShadowMap(v.shadowMap, sub, gridBuilt, [&] { cuda::parallelFor(columns, ShadowMapKernel{v.shadowMap, grid_, sub}, compute_, 128); });
    }
    if (shade.farStart >= 0.0f && farFieldReachable(scene, shade, camera)) {
      // the far field: once per scene (it depends on the instances and sigma only), once a cone can reach it
      if (farValues_.size() == 0 || farSigma_ != shade.sigma) {
        far_ = scene.far;
        const int64_t n = int64_t(far_.dim[0]) * far_.dim[1] * far_.dim[2];
        CANOPY_CUDA_CHECK(cudaStreamSynchronize(compute_));
        farValues_.resize(size_t(n) * kFarFieldChannels);
        far_.values = farValues_.data();
        cuda::parallelFor(n, FarFieldKernel{v, far_}, compute_, 128);
        farSigma_ = shade.sigma;
      }
      v.far = far_;
    }
    lastShadowMap_ = v.shadowMap;
    view_ = v;
    const int tilesX = (camera.width + tileW_ - 1) / tileW_, tilesY = (band.rows() + tileH_ - 1) / tileH_;
    const int64_t threads = int64_t(tilesX) * tilesY * tileW_ * tileH_;
    // one kernel per shadow path and per light (renderPixelT): the map's kernel for a scene
    // without lit models has neither shadow-cone nor LB light code
    float* out = image_[eye].data();
    lastFilled_ = 0;
    if (depth)
      launchMode<true>(scene, shade, camera, out, band, nullptr, threads, depth, disparityScale);
    else if (adaptive_ > 0.0f && eye == 0)
      renderAdaptive(scene, shade, camera, out, band, tilesX, threads);
    else
      launchMode<false>(scene, shade, camera, out, band, nullptr, threads, nullptr, 0.0f);
    CANOPY_CUDA_CHECK(cudaStreamSynchronize(compute_));
  }
  // adaptive.h: the lattice; each block of the band tested; the passing blocks' off-lattice pixels
  // filled, the failing blocks' traced (in tile order: a warp's rays stay within two blocks).
  void renderAdaptive(const HostScene& scene, const ShadeParams& shade, const CameraView& camera, float* out, Band band, int tilesX,
                      int64_t threads) {
    Band rows;  // the rows of the band's blocks, whose lattice the blocks' tests read
    adaptiveBlockRows(band.y0, band.y1, tileH_, camera.height, rows.y0, rows.y1);
    const int latticeTilesX = (adaptiveLatticeWidth(camera.width) + tileW_ - 1) / tileW_;
    const int latticeRows = adaptiveLatticeEnd(rows.y1, camera.height) - adaptiveLatticeFirst(rows.y0);
    const int latticeTilesY = (latticeRows + tileH_ - 1) / tileH_;
    launchMode<false>(scene, shade, camera, out, rows, nullptr, int64_t(latticeTilesX) * latticeTilesY * tileW_ * tileH_, nullptr, 0.0f, true);
    const int blockRow0 = adaptiveBlockRowFirst(band.y0, tileH_), blockRows = adaptiveBlockRowEnd(band.y1, tileH_) - blockRow0;
    const int64_t blocks = int64_t(tilesX) * blockRows;
    if (blockPass_.size() < size_t(blocks)) blockPass_.resize(size_t(blocks));
    cuda::parallelFor(blocks, AdaptiveBlockKernel{out, camera.width, camera.height, tileW_, tileH_, tilesX, blockRow0, adaptive_, blockPass_.data()},
                      compute_, 128);
    if (hole_.size() < size_t(threads)) hole_.resize(size_t(threads)), holeList_.resize(size_t(threads));
    cuda::parallelFor(threads,
                      AdaptiveFillKernel{out, camera.width, tilesX, tileW_, tileH_, band.y0, band.y1, blockRow0, blockPass_.data(), hole_.data()},
                      compute_, 256);
    const int64_t traced = compactHoles(threads);
    launchMode<false>(scene, shade, camera, out, band, holeList_.data(), traced, nullptr, 0.0f);
    lastFilled_ = adaptiveOffLattice(camera.width, band.y0, band.y1) - uint64_t(traced);
  }
  // The marks hole_[0, marks) that are >= 0, in order, into holeList_; returns their count (waits
  // for the compute stream).
  int64_t compactHoles(int64_t marks) {
    size_t tempBytes = 0;
    CANOPY_CUDA_CHECK(cub::DeviceSelect::If(nullptr, tempBytes, hole_.data(), holeList_.data(), holeCount_.data(), marks, IsHole{}, compute_));
    if (selectTemp_.size() < tempBytes) selectTemp_.resize(tempBytes);
    CANOPY_CUDA_CHECK(cub::DeviceSelect::If(selectTemp_.data(), tempBytes, hole_.data(), holeList_.data(), holeCount_.data(), marks, IsHole{},
                                            compute_));
    int64_t holes = 0;
    CANOPY_CUDA_CHECK(cudaMemcpyAsync(&holes, holeCount_.data(), sizeof holes, cudaMemcpyDeviceToHost, compute_));
    CANOPY_CUDA_CHECK(cudaStreamSynchronize(compute_));
    return holes;
  }
  // The pixel kernel of the mode (shadow path, LB light, stereo's depth or holes) over `threads`
  // tile positions of the band (or list[0, threads) of them), with view_.
  template <bool kWithDepth, bool kBehind = false>
  void launchMode(const HostScene& scene, const ShadeParams& shade, const CameraView& camera, float* out, Band band, const int32_t* list,
                  int64_t threads, float* stereo, float disparityScale, bool lattice = false) {
    const int tilesX = ((lattice ? adaptiveLatticeWidth(camera.width) : camera.width) + tileW_ - 1) / tileW_;
    if (shade.shadows == kShadowsCone) {
      launchPixels<5>(PixelKernel<true, true, kWithDepth, kBehind>{view_, camera, out, tilesX, tileW_, tileH_, band.y0, band.y1, list, stereo, disparityScale, lattice},
                      threads, compute_);
    } else if (scene.litModels > 0) {
      launchMap(PixelKernel<false, true, kWithDepth, kBehind>{view_, camera, out, tilesX, tileW_, tileH_, band.y0, band.y1, list, stereo, disparityScale, lattice},
                threads);
    } else {
      launchMap(PixelKernel<false, false, kWithDepth, kBehind>{view_, camera, out, tilesX, tileW_, tileH_, band.y0, band.y1, list, stereo, disparityScale, lattice},
                threads);
    }
  }
  // The map's (or no-shadow) kernel at the occupancy asked for (setPixelOccupancy); the traced
  // eye's with depth at 6 blocks without LB light and unconstrained with it (the mono lit kernel's 5
  // blocks are not measured there), the holes' at setStereoHoles's.
  // Each with the frame's paths only (scenePaths; stereo's kernels stereoPaths), but those of an
  // occupancy asked for with setPixelOccupancy, which have every path.
  template <bool kWithLight, bool kWithDepth, bool kBehind>
  void launchMap(const PixelKernel<false, kWithLight, kWithDepth, kBehind>& k, int64_t threads) {
    const uint32_t paths = scenePaths(k.scene);
    if constexpr (kBehind) {
      if (holeMinBlocks_ >= 6)
        launchOfPaths<6>(stereoPaths(paths), k, threads);
      else
        launchOfPaths<0>(stereoPaths(paths), k, threads);
    } else if constexpr (kWithDepth) {
      launchOfPaths<kWithLight ? 0 : 6>(stereoPaths(paths), k, threads);
    } else {
      if (minBlocks_ == 0)
        launchOfPaths<kWithLight ? 5 : 6>(paths, k, threads);
      else if (minBlocks_ >= 8)
        launchPixels<8>(k, threads, compute_);
      else if (minBlocks_ >= 6)
        launchPixels<6>(k, threads, compute_);
      else
        launchPixels<0>(k, threads, compute_);
    }
  }
  // The kernel of k's mode compiled with the optional paths `paths` only (kPaths runs over the mode's
  // path sets up to it: nextPathSet).
  template <int kMinBlocks, uint32_t kPaths = 0, bool kWithLight, bool kWithDepth, bool kBehind>
  void launchOfPaths(uint32_t paths, const PixelKernel<false, kWithLight, kWithDepth, kBehind>& k, int64_t threads) {
    if constexpr (kPaths < kAllPaths) {
      if (paths != kPaths) return launchOfPaths<kMinBlocks, nextPathSet(kPaths, kWithDepth || kBehind)>(paths, k, threads);
    }
    launchPixels<kMinBlocks>(PixelKernel<false, kWithLight, kWithDepth, kBehind, kPaths>{k.scene, k.camera, k.out, k.tilesX, k.tileW, k.tileH,
                                                                                          k.y0, k.y1, k.list, k.stereo, k.disparityScale, k.lattice},
                             threads, compute_);
  }
  StereoCounts reprojectRows(const HostScene& scene, const CameraView& right, uint32_t stamp, Band band, const StereoParams& p) override {
    (void)stamp;  // view_'s, the last render of this pass
    const auto t0 = std::chrono::steady_clock::now();
    CANOPY_CUDA_CHECK(cudaSetDevice(device_));
    const size_t pixels = size_t(right.width) * right.height;
    if (image_[1].size() != pixels * 4) image_[1].resize(pixels * 4);
    if (keys_.size() != pixels) keys_.resize(pixels), behind_.resize(pixels), cover_.resize(pixels), holeFrom_.resize(pixels);
    const size_t first = size_t(band.y0) * right.width, count = size_t(band.rows()) * right.width;
    CANOPY_CUDA_CHECK(cudaMemsetAsync(behindCount_.data(), 0, sizeof(unsigned long long), compute_));
    CANOPY_CUDA_CHECK(cudaMemsetAsync(keys_.data() + first, 0, count * sizeof(unsigned long long), compute_));
    CANOPY_CUDA_CHECK(cudaMemsetAsync(behind_.data() + first, 0, count * sizeof(unsigned long long), compute_));
    CANOPY_CUDA_CHECK(cudaMemsetAsync(cover_.data() + first, 0, count * sizeof(uint32_t), compute_));
    const StereoView sv =
        stereoView(image_[0].data(), disparity_.data(), keys_.data(), behind_.data(), cover_.data(), image_[1].data(), right.width, p);
    cuda::parallelFor(int64_t(count), StereoSplatKernel{sv, band.y0}, compute_, 256);
    cuda::parallelFor(int64_t(count), StereoBehindKernel{sv, band.y0}, compute_, 256);
    const int tilesX = (right.width + tileW_ - 1) / tileW_, tilesY = (band.rows() + tileH_ - 1) / tileH_;
    const int64_t threads = int64_t(tilesX) * tilesY * tileW_ * tileH_;
    const int64_t marks = 2 * threads;
    if (hole_.size() < size_t(marks)) hole_.resize(size_t(marks)), holeList_.resize(size_t(marks));
    cuda::parallelFor(threads,
                      StereoResolveKernel{sv, tilesX, tileW_, tileH_, band.y0, band.y1, hole_.data(), threads, holeOrder_, holeFrom_.data(),
                                          behindCount_.data()},
                      compute_, 256);
    unsigned long long behind = 0;
    CANOPY_CUDA_CHECK(cudaMemcpyAsync(&behind, behindCount_.data(), sizeof behind, cudaMemcpyDeviceToHost, compute_));
    const int64_t holes = compactHoles(marks);
    const double reprojectS = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    launchMode<false, true>(scene, view_.shade, right, image_[1].data(), band, holeList_.data(), holes, holeFrom_.data(), disparityScale_);
    CANOPY_CUDA_CHECK(cudaStreamSynchronize(compute_));
    return StereoCounts{uint64_t(holes), uint64_t(behind), reprojectS};
  }
  void readStamps(std::vector<uint32_t>& slotUsed, std::vector<uint32_t>& pageWanted) override {
    CANOPY_CUDA_CHECK(cudaSetDevice(device_));
    slotUsed.resize(slots_);
    pageWanted.resize(pageCount_);
    if (slots_) slotUsed_.download(slotUsed.data(), slots_);
    if (pageCount_) pageWanted_.download(pageWanted.data(), pageCount_);
  }
  void setPixelOccupancy(int minBlocks) override { minBlocks_ = minBlocks; }
  void setStereoHoles(int order, int minBlocks) override { holeOrder_ = order, holeMinBlocks_ = minBlocks; }
  void readRows(std::vector<float>& rgba, int eye, Band band, int width) override {
    CANOPY_CUDA_CHECK(cudaSetDevice(device_));
    const size_t first = size_t(band.y0) * width * 4, count = size_t(band.rows()) * width * 4;
    if (count) CANOPY_CUDA_CHECK(cudaMemcpy(rgba.data() + first, image_[eye].data() + first, count * sizeof(float), cudaMemcpyDeviceToHost));
  }

 private:
  uint32_t pageBytes_, pageCount_, slots_ = 0;
  int minBlocks_ = 0;
  int holeOrder_ = kHoleOrderKind, holeMinBlocks_ = 6;  // setStereoHoles
  cudaStream_t compute_ = nullptr, copy_ = nullptr;
  cudaEvent_t tableCopied_[2] = {nullptr, nullptr};
  int mirror_ = 0;
  cuda::DeviceBuffer<CanopyNode> tiles_;
  cuda::DeviceBuffer<uint32_t> sparseIndex_;  // CanopyFile::sparseIndex(): the detail models' sparse brick locations
  cuda::DeviceBuffer<uint32_t> haarIndex_;  // CanopyFile::haarIndex(): the Haar-lit models' group tables and locations
  cuda::DeviceBuffer<CanopyNode> levelNodes_;  // the models' descent tables (HostScene::levelNodes)
  cuda::DeviceBuffer<uint8_t> levelOf_;
  cuda::DeviceBuffer<uint32_t> lightBricks_;
  cuda::DeviceBuffer<ModelView> models_;
  cuda::DeviceBuffer<InstanceView> instances_;
  cuda::DeviceBuffer<uint32_t> gridStart_, gridItems_, gridFaceStart_, gridFaceItems_;
  cuda::DeviceBuffer<SceneLightPair> light_;  // the scene light's factor pairs (HostScene::lightPairs)
  uint64_t lightVersion_ = 0;                  // the HostScene::lightVersion that light_ holds
  cuda::DeviceBuffer<unsigned char> pool_;
  cuda::DeviceBuffer<int32_t> table_;
  cuda::DeviceBuffer<uint32_t> slotUsed_, pageWanted_;
  cuda::DeviceBuffer<float> image_[2], disparity_, shadowMap_, extinction_, farValues_;
  cuda::DeviceBuffer<unsigned long long> keys_, behind_;  // stereo: per right-eye pixel, the nearest front span and the nearest span behind it (stereo.h)
  cuda::DeviceBuffer<uint32_t> cover_;
  cuda::DeviceBuffer<int32_t> hole_, holeList_;   // stereo's holes' marks by half and tile position (adaptive sampling's by tile
                                                  // position), and compacted
  cuda::DeviceBuffer<uint8_t> blockPass_;         // adaptive sampling: the band's blocks, 1 where filled
  cuda::DeviceBuffer<int64_t> holeCount_;
  cuda::DeviceBuffer<unsigned long long> behindCount_;  // stereo: the holes traced behind a reprojected front
  cuda::DeviceBuffer<float> holeFrom_;                  // stereo: per right-eye hole, where its trace starts
  float disparityScale_ = 0.0f;                         // the traced eye's (renderRows)
  cuda::DeviceBuffer<unsigned char> selectTemp_;
  SceneView view_{};  // the last render's view (its stamp, shade and shadow map): the second eye's holes use it
  int device_ = 0;
  ExtinctionGridView grid_{};
  float gridSigma_ = -1.0f, gridCells_ = -1.0f;
  uint32_t gridCap_ = 0;
  FarFieldView far_{};
  float farSigma_ = -1.0f;
  unsigned char* staging_ = nullptr;
  int32_t* tableHost_[2] = {nullptr, nullptr};
};

}  // namespace

std::unique_ptr<Backend> makeCudaBackend(const HostScene& scene, uint32_t slots, int deviceIndex) {
  return std::make_unique<CudaBackend>(scene, slots, deviceIndex < 0 ? 0 : deviceIndex);
}

}  // namespace canopy::play
