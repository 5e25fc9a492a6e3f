// backend.h: what the frame loop needs from a renderer (CPU reference or CUDA).
//
// A backend owns the page pool (slots of pageBytes), the page table (page -> slot or -1), the use
// and want stamps that rays write, the staging buffers the loader reads pages into, and the images
// (two eyes). The CPU backend keeps all of it in host memory; the CUDA backend keeps the pool,
// table, stamps, node tiles and scene on the device, stages pages in pinned host memory and copies
// them on a copy stream that the next frame's kernel waits for (cudaStreamWaitEvent), so a frame
// never waits for the disk and uploads never race a kernel.
//
// A backend renders a band of rows of the frame (tiles.h: one band per GPU); its images are the
// whole frame's size, of which only the band's rows are written and read back.
#pragma once
#include <cstdint>
#include <cstring>
#include <memory>
#include <string>
#include <vector>

#include "runtime/scene.h"
#include "runtime/stereo.h"
#include "runtime/tiles.h"

namespace canopy::play {

// What a stereo second eye traced (Backend::reprojectRows): its holes, and of them those traced
// only behind a reprojected front; and the seconds its reprojection took (the splats, the resolve
// and the hole list, until the holes' trace is launched).
struct StereoCounts {
  uint64_t traced = 0, behind = 0;
  double reprojectS = 0.0;
};

class Backend {
 public:
  virtual ~Backend() = default;
  virtual std::string name() const = 0;
  // Host memory for `count` staging pages (pinned on CUDA), owned by the backend.
  virtual unsigned char* stagingBuffers(uint32_t count) = 0;
  // Enqueues the copy of a staged page into pool slot `slot`.
  virtual void upload(uint32_t slot, const unsigned char* staged) = 0;
  // Publishes the page table; ordered after every upload() before it and before the next render().
  virtual void setPageTable(const std::vector<int32_t>& table) = 0;
  // Waits until the staging buffers passed to upload() may be reused.
  virtual void waitUploads() = 0;
  // Renders the rows `band` of one pass into eye `eye`'s image (0, or 1: stereo's second eye traced
  // in full) (scene.instances carry this frame's sun weights). disparityScale > 0: also records each
  // pixel's disparity for reprojection (stereo.h; eye 0 only).
  virtual void renderRows(const HostScene& scene, const ShadeParams& shade, const CameraView& camera, uint32_t stamp, Band band,
                          int eye, float disparityScale) = 0;
  // Stereo's second eye over `band`: reprojects eye 0 (rendered with a disparityScale by the last
  // renderRows of this pass) into eye 1 and traces its holes with `right` (the same stamp, shade
  // and shadow map as that render). Returns the number of pixels traced, and of them those traced
  // only behind a reprojected front (stereoResolveHole).
  virtual StereoCounts reprojectRows(const HostScene& scene, const CameraView& right, uint32_t stamp, Band band, const StereoParams& p) = 0;
  // Copies the stamps written by the last render() to the host.
  virtual void readStamps(std::vector<uint32_t>& slotUsed, std::vector<uint32_t>& pageWanted) = 0;
  // Copies eye `eye`'s rows `band` into rgba (width * height RGBA floats, premultiplied RGB,
  // alpha = 1 - T; the caller sizes it).
  virtual void readRows(std::vector<float>& rgba, int eye, Band band, int width) = 0;
  // The order in which stereo's second eye traces its holes (CUDA only: kHoleOrder*, stereo.h's
  // stereoHoleHalf; kHoleOrderKind by default) and its kernel's occupancy (6: built for at least 6
  // blocks of 128 per SM, the default; 0: unconstrained). Neither changes the image.
  virtual void setStereoHoles(int order, int minBlocks) { (void)order, (void)minBlocks; }
  // The pixels one GPU warp renders: a w x h tile, w h = 32 (4x8 by default). The CUDA kernels'
  // warp tiles, and adaptive sampling's blocks on both backends (adaptive.h).
  void setPixelTile(int w, int h) { tileW_ = w, tileH_ = h; }
  // Adaptive sampling (adaptive.h) of the renders of eye 0 without depth: tol > 0 traces the
  // lattice, fills each block whose cells' corners agree within tol and traces the other blocks'
  // pixels; 0 (the default) traces every pixel.
  void setAdaptive(float tol) { adaptive_ = tol; }
  // The pixels of the last renderRows' band that were filled, not traced (adaptive sampling).
  uint64_t lastFilled() const { return lastFilled_; }
  // CUDA: the pixel kernel compiled for at least this many blocks of 128 threads per SM (6 or 8; -1:
  // unconstrained; 0, the default: 6 without LB light, 5 with it; map and no-shadow modes; a timing knob)
  virtual void setPixelOccupancy(int minBlocks) { (void)minBlocks; }
  // Counts the work of the following renders into `work` (CPU reference only; others ignore it).
  virtual void countWork(WorkCounters* work) { (void)work; }
  // The last render's sun transmittance map (kShadowsMap; dim all 1 otherwise).
  const ShadowMapView& lastShadowMap() const { return lastShadowMap_; }
  // Shadow-map builds since the backend was made (kShadowsMap: one per sun direction and scene).
  uint64_t shadowMapBuilds() const { return shadowMapBuilds_; }

  // The whole frame, one eye (tests, single-band use).
  void render(const HostScene& scene, const ShadeParams& shade, const CameraView& camera, uint32_t stamp) {
    renderRows(scene, shade, camera, stamp, Band{0, camera.height}, 0, 0.0f);
  }
  void readImage(std::vector<float>& rgba, const CameraView& camera) {
    rgba.assign(size_t(camera.width) * camera.height * 4, 0.0f);
    readRows(rgba, 0, Band{0, camera.height}, camera.width);
  }

 protected:
  // Calls build() to build the pass's shadow map m (planShadowMap, `sub` steps per voxel, its
  // storage in m.T) unless the last build made the same map: its columns depend only on the plan
  // (the sun's direction, the scene's box, the voxel, the steps), the storage and the extinction
  // grid (gridBuilt: built again for this pass), so a map built for the same plan into the same
  // storage is kept, the same bits. A sun that does not move costs one build, not one per frame.
  template <class Build>
  void buildShadowMap(const ShadowMapView& m, int sub, bool gridBuilt, Build&& build) {
    const ShadowMapView& b = builtShadowMap_;
    const auto same = [](const void* x, const void* y, size_t n) { return std::memcmp(x, y, n) == 0; };
    const bool kept = !gridBuilt && builtShadowMapSub_ == sub && b.T == m.T && same(&b.origin, &m.origin, sizeof(V3)) &&
                      same(b.axis, m.axis, sizeof(b.axis)) && same(&b.voxel, &m.voxel, sizeof(float)) && same(b.dim, m.dim, sizeof(b.dim));
    if (kept) return;
    build();
    builtShadowMap_ = m, builtShadowMapSub_ = sub;
    ++shadowMapBuilds_;
  }
  ShadowMapView lastShadowMap_{};
  ShadowMapView builtShadowMap_{};
  int builtShadowMapSub_ = 0;  // 0: none built
  uint64_t shadowMapBuilds_ = 0;
  int tileW_ = kDefaultWarpTileWidth, tileH_ = 32 / kDefaultWarpTileWidth;
  float adaptive_ = 0.0f;
  uint64_t lastFilled_ = 0;
};

std::unique_ptr<Backend> makeCpuBackend(const HostScene& scene, uint32_t slots);
// Throws canopy::Error(Unsupported) in a build without CUDA.
std::unique_ptr<Backend> makeCudaBackend(const HostScene& scene, uint32_t slots, int deviceIndex);

}  // namespace canopy::play
