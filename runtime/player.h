// player.h: canopy-play's callable core (main.cpp only parses arguments).
//
// play() opens a .canopy file, builds the scene, renders `frames` frames along a camera path and a
// sun path with the chosen backend and the streaming cache, writes the frames and returns the
// report (frame times, cache statistics). Tests and the benchmark call it in-process.
#pragma once
#include <cstdint>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "canopy/device.h"
#include "runtime/cone.h"
#include "runtime/scene.h"
#include "runtime/stereo.h"
#include "runtime/tiles.h"

namespace canopy::play {

struct PlayOptions {
  std::string input;                 // FILE.canopy
  std::string output;                // out.png | out.exr | frames/f_%04d.exr ("" = no output)
  int width = 640, height = 360;
  int frames = 1;
  std::string camera = "orbit";      // orbit[:key=value,...] | path.json
  std::string sun = "orbit:azimuth=40,elevation=50";  // x,y,z (towards the sun) | orbit:... | path.json
  double cacheMb = 1024.0;           // page pool budget (brick and light pages share it)
  float sigma = 4.0f;                // extinction per lattice cell at density 1
  float ambient = 0.35f;             // ambient (indirect) factor
  float sunIntensity = 1.0f;
  bool directSun = true;             // false (--no-direct-sun): only the indirect (LB and ambient) light
  float stepFactor = 0.5f;           // brick step, in voxels of the chosen level
  float lodBias = 0.0f;
  float stepGrowthT = 0.1f;          // --step-growth: brick steps grow below this transmittance (0: never; ShadeParams)
  float stepGrowthMax = 4.0f;        // --step-growth-max: by at most this factor
  // The far field (cone.h farFieldStep): "auto" (from where a cone's footprint reaches the
  // coarsest level's voxel of the coarsest instance), "off" (instances everywhere) or a distance D
  // (scene units, > 0): the prefiltered scene volume from D on.
  std::string farField = "auto";
  float stopTransmittance = kStopT;   // a cone stops below this transmittance (--stop-opacity 1 - this); the rest is dropped
  // Adaptive sampling (adaptive.h; one eye only): "auto" (kAdaptiveAutoTolerance on frames of at least
  // kAdaptiveAutoPixels pixels without --stereo or --converge, else every pixel traced), "off" or 0
  // (every pixel traced), or a tolerance TOL > 0. adaptiveTolerance() resolves it.
  std::string adaptive = "auto";
  float shadowAperture = 0.03f;      // shadow cone growth per unit length (soft shadows, coarser
                                     // levels and longer steps far from the receiver)
  bool shadows = true;
  std::string shadowMethod = "map";  // map: per-frame sun transmittance map; cone: a shadow cone per
                                     // shadow interval (the exact, slow reference)
  float shadowMapCells = 4.0f;       // extinction grid voxel in lattice cells of the finest instance...
  float shadowMapBias = 0.0f;        // map lookups move this many blur widths (the larger of a map voxel
                                     // and a finest node) towards the sun
  uint32_t shadowMapMaxVoxels = 1u << 23;  // ...grown until the grid (and the map) has at most this many voxels
  bool descentCache = true;          // reuse a ray's last octree descent per instance (same image, fewer descents)
  bool descentTable = true;          // build the models' descent tables and read a descent's node from them where that is the same descent (same image)
  bool holdEmpty = true;             // keep an instance's empty leaf segment over later steps (same image, cone.h EmptyHold)
  bool skipEmptyBlocks = true;       // a brick step in an empty one-voxel cell goes to the end of the cell run (cone.h emptyRunEnd)
  bool exactLight = false;           // --light exact: the finest level of Haar-lit models from their Haar pages (the .chaar's values)
  int pixelMinBlocks = 0;            // CUDA, map/no shadows: pixel kernel built for >= 6 or 8 blocks of 128 per SM, -1 unconstrained (0: the default, 6 without LB light, 5 with it)
  int warpTileWidth = kDefaultWarpTileWidth;  // CUDA: a warp renders a warpTileWidth x (32 / warpTileWidth) tile
  std::string stereoHoleOrder = "kind";  // CUDA: the order stereo's holes are traced in: tile or kind (Backend::setStereoHoles)
  int stereoHoleBlocks = 6;              // CUDA: the holes' kernel built for >= 6 blocks of 128 per SM, or 0: unconstrained
  bool countWork = false;            // CPU only: count cones, steps, samples, shadow work (report "work")
  float background[3] = {0.60f, 0.72f, 0.85f};  // linear RGB behind the scene (PNG only)
  // The ground plane (cone.h groundRadiance): "none", "auto" (at the lowest instance base,
  // HostScene::groundBase) or a world height Y; its albedo (linear RGB, each in [0, 1]).
  std::string ground = "auto";
  float groundAlbedo[3] = {0.20f, 0.17f, 0.13f};
  bool converge = false;             // per frame, render passes until no loadable page is missing
  bool warmStart = true;             // the first frame converges (a complete first image), the
                                     // rest are real-time (one pass, loads land in later frames)
  int loaderThreads = 0;             // page reader threads per band; 0: loaderThreadsFor's (the host's threads)
  uint32_t stagingPages = 256;       // pages read ahead per pass at most (16 MiB pinned)
  // Stereo (stereo.h): --stereo IPD renders a left and a right eye IPD scene units apart; the left
  // is traced, the right reprojected from it with its holes traced (stereoFill "reproject"), or
  // traced in full ("trace": the reference the reprojection is measured against).
  float stereoIpd = 0.0f;            // 0: one eye
  std::string stereoFill = "reproject";
  StereoParams stereo;               // --stereo-spread: stereo.maxSpread
  std::string rightOutput;           // the right eye's frames; "" = both eyes side by side in `output`
  // Bands (tiles.h): the frame cut into this many bands of rows over the renderers (round robin),
  // each band with its own renderer, cache and loader, rebalanced every frame. 0: one per renderer
  // (every GPU of --device cuda, else one).
  int tiles = 0;
};

// A frame's camera and sun.
struct FrameSetup {
  CameraView camera;
  V3 toSun;
};

// Evaluates --camera and --sun for frame f of n over the scene's bounds. Throws canopy::Error(Usage)
// for a bad spelling, (Io/InvalidInput) for a bad path file.
std::vector<FrameSetup> framePlan(const PlayOptions& o, const HostScene& scene);

// The file name of frame f >= 0. A name without '%' is used as it is (one frame only); otherwise it is
// a pattern with exactly one integer conversion %d, %Nd or %0Nd (N <= 32) and "%%" for a literal '%',
// which this function formats itself (the pattern never reaches printf). Throws Usage naming the
// pattern for anything else (%s, %n, two conversions, ...) and for several frames without a pattern.
std::string frameFileName(const std::string& pattern, int frame, int frames);

// The page reader threads of each band: `requested` where > 0, else the host's hardware threads
// shared by the bands, at least 2 and at most 16 each (decoding and checking pages is the cold
// start's cost: bench/RESULTS.md, "Detail lattices").
int loaderThreadsFor(int requested, int bands);

// Runs everything; `lastImage` (optional) receives the last frame's RGBA (with --stereo the left
// eye's, and `lastRight` the right eye's). A run that fails removes the frames it has written, so a
// failed run leaves no output (each frame is written atomically). A plain "cuda" device renders on
// every GPU, a band each (tiles.h).
nlohmann::json play(const PlayOptions& o, const Device& device, std::vector<float>* lastImage = nullptr,
                    std::vector<float>* lastRight = nullptr);

// --adaptive "auto": adaptive sampling at this tolerance on frames of at least this many pixels
// (3840x2160), where the footprint rule samples voxels that span several pixels and the lattice's
// rays see what a 1920x1080 frame's do (docs/play.md, "Adaptive sampling").
constexpr float kAdaptiveAutoTolerance = 0.08f;
constexpr uint64_t kAdaptiveAutoPixels = uint64_t(3840) * 2160;

// The adaptive sampling tolerance of the options (0: every pixel traced). Throws Usage for a bad
// spelling, a tolerance outside [0, 1000], and a tolerance > 0 given with --stereo.
float adaptiveTolerance(const PlayOptions& o);

// The per-sample parameters of the options (everything but the frame's sun direction, toSun, and
// the ground, setGround).
ShadeParams shadeParams(const PlayOptions& o);

// The ground of --ground over this scene into shade (ground, groundY, groundAlbedo); "auto" on a
// scene without matter is no ground. Throws Usage for a bad spelling.
void setGround(const PlayOptions& o, const HostScene& scene, ShadeParams& shade);

}  // namespace canopy::play
