// main.cpp: canopy-play's command line; the work is in player.cpp.
#include <cstdio>
#include <string>

#include "canopy/cli.h"
#include "runtime/player.h"

namespace {

// The command line's values that are not PlayOptions fields as they stand (parsed or inverted in
// applyValues).
struct CliValues {
  std::string size = "640x360";
  double stopOpacity = 1.0 - double(canopy::play::kStopT);
  bool noShadows = false;
  bool noDirect = false;
  bool noDescentCache = false;
  bool noDescentTable = false;
  bool noEmptySkip = false;
  std::string lightMode = "fast";
  std::string groundAlbedo = "0.2,0.17,0.13";
  bool coldStart = false;
};

// The input, output, frames, camera and shading options.
void addFrameOptions(CLI::App& app, canopy::play::PlayOptions& o, CliValues& x) {
  app.add_option("input", o.input, "FILE.canopy")->required();
  app.add_option("-o,--output", o.output, "out.png | out.exr | frames/f_%04d.exr (several frames: one %d, %Nd or %0Nd; %% for a literal %)");
  app.add_option("--size", x.size, "Frame size WxH")->capture_default_str();
  app.add_option("--frames", o.frames, "Number of frames")->capture_default_str();
  app.add_option("--camera", o.camera, "orbit[:azimuth=,elevation=,distance=,height=,fov=,turns=] or a keyframe path.json")
      ->capture_default_str();
  app.add_option("--sun", o.sun, "x,y,z (towards the sun), orbit[:azimuth=,elevation=,turns=] or a keyframe path.json")
      ->capture_default_str();
  app.add_option("--cache-mb", o.cacheMb, "Page cache budget (MiB; brick and light pages share it)")->capture_default_str();
  app.add_option("--sigma", o.sigma, "Extinction per lattice cell at density 1")->capture_default_str();
  app.add_option("--ambient", o.ambient, "Ambient factor: times B_0 of LB-lit models, the whole indirect term of density-only ones")->capture_default_str();
  app.add_option("--sun-intensity", o.sunIntensity, "Sun radiance")->capture_default_str();
  app.add_option("--step", o.stepFactor, "Brick step in voxels of the chosen level")->capture_default_str();
  app.add_option("--lod-bias", o.lodBias, "Added to the footprint's level (negative = coarser)")->capture_default_str();
  app.add_option("--step-growth", o.stepGrowthT,
                 "Brick steps grow once a cone's transmittance T falls below this T0: by T0 / T, at most --step-growth-max (0: never)")
      ->capture_default_str()->check(CLI::Range(0.0, 1.0));
  app.add_option("--step-growth-max", o.stepGrowthMax, "The most brick steps grow (--step-growth)")->capture_default_str()->check(CLI::Range(1.0, 64.0));
  app.add_option("--far-field", o.farField,
                 "auto: instances up to where a pixel's footprint exceeds the coarsest voxel of every instance, a prefiltered scene "
                 "volume beyond (its cost no longer grows with the instances passed); off: instances everywhere; or a distance D: the volume from D on")
      ->capture_default_str();
  app.add_option("--stop-opacity", x.stopOpacity, "A cone stops at this opacity; at most 1 - this of a pixel's light is dropped")
      ->default_str("0.999")->check(CLI::Range(0.5, 1.0));
  app.add_option("--adaptive", o.adaptive,
                 "auto | off | TOL. Adaptive sampling: trace every second pixel of every second row, then fill each 4x8 block whose "
                 "2x2 cells' traced corners differ by at most TOL in every channel (linear premultiplied RGBA) and trace the other "
                 "blocks. auto: TOL 0.08 on frames of 3840x2160 pixels or more (one eye, without --converge), else off; "
                 "off or 0: trace every pixel (docs/play.md)")
      ->capture_default_str();
}

// The shadow options, and the benchmarks' timing knobs (hidden from --help).
void addShadowOptions(CLI::App& app, canopy::play::PlayOptions& o, CliValues& x) {
  app.add_option("--shadow-aperture", o.shadowAperture, "Shadow cone aperture (radians)")->capture_default_str();
  app.add_flag("--no-shadows", x.noShadows, "Direct sun unshadowed");
  app.add_flag("--no-direct-sun", x.noDirect, "Leave the direct sun out: indirect light only (the LB bases and ambient), to inspect it");
  app.add_option("--shadows", o.shadowMethod, "map: per-frame sun transmittance map; cone: a shadow cone per shadow interval (slow reference)")
      ->capture_default_str();
  app.add_option("--shadow-map-cells", o.shadowMapCells, "Shadow extinction grid voxel in lattice cells of the finest instance")->capture_default_str();
  app.add_option("--shadow-map-bias", o.shadowMapBias, "Shadow map lookups move this many blur widths (the larger of a map voxel and a finest node) towards the sun")->capture_default_str();
  // Timing knobs for the benchmarks (same image, or the images before a change): hidden from --help,
  // documented in docs/play.md.
  app.add_option("--warp-tile", o.warpTileWidth, "CUDA: a warp renders a W x (32/W) pixel tile")->capture_default_str()->group("");
  app.add_option("--stereo-holes", o.stereoHoleOrder, "CUDA: the order stereo's holes are traced in: tile or kind")
      ->capture_default_str()
      ->group("");
  app.add_option("--stereo-hole-blocks", o.stereoHoleBlocks, "CUDA: the holes' kernel built for >= 6 blocks per SM, or 0: unconstrained")
      ->capture_default_str()
      ->group("");
  app.add_flag("--no-descent-cache", x.noDescentCache, "Descend the octree from the root for every segment (same image; for timing)")->group("");
  app.add_flag("--no-descent-table", x.noDescentTable,
               "Descend from the root instead of reading a descent's node from the model's descent table (same image; for timing)")
      ->group("");
  app.add_flag("--no-empty-skip", x.noEmptySkip,
               "March the empty cells of bricks in half-voxel steps instead of skipping them (the sample phase changes by 0.1-0.4 % RMS; for comparison)")
      ->group("");
  app.add_option("--shadow-map-voxels", o.shadowMapMaxVoxels, "Shadow map size cap (the voxel grows to fit)")->capture_default_str();
}

// The light, ground, convergence and loader options.
void addLightOptions(CLI::App& app, canopy::play::PlayOptions& o, CliValues& x) {
  app.add_option("--light", x.lightMode,
                 "fast: LB light from the light items on every level; exact: at the finest level, from the .chaar's Haar "
                 "bricks where the file has them (the .chaar's own samples; a little slower, docs/play.md)")
      ->check(CLI::IsMember({"fast", "exact"}))
      ->capture_default_str();
  app.add_option("--ground", o.ground,
                 "none, auto (a plane at the lowest instance base: the bottom of its lowest occupied cell) or a height Y; it takes the "
                 "sun's shadow and the scene light's sky occlusion")
      ->capture_default_str();
  app.add_option("--ground-albedo", x.groundAlbedo, "The ground's albedo: R,G,B or one value, linear, in [0, 1]")->capture_default_str();
  app.add_flag("--converge", o.converge, "Per frame, render passes until no loadable page is missing (reference quality)");
  app.add_flag("--no-warm-start", x.coldStart, "Render the first frame in real-time mode too (node means until pages arrive)");
  app.add_option("--loader-threads", o.loaderThreads,
                 "Page reader threads per band (0: the host's hardware threads shared by the bands, 2 to 16 each)")
      ->capture_default_str()
      ->check(CLI::Range(0, 64));
}

// The stereo and band options.
void addStereoOptions(CLI::App& app, canopy::play::PlayOptions& o) {
  app.add_option("--stereo", o.stereoIpd,
                 "Render a stereo pair, the eyes IPD scene units apart (0.064 for people in a scene in metres): the left eye traced, "
                 "the right reprojected from it and only its holes traced; side by side in -o unless --right-output is given");
  app.add_option("--right-output", o.rightOutput, "With --stereo: the right eye's frames (a name or pattern as -o); -o then holds the left eye");
  app.add_option("--stereo-fill", o.stereoFill, "reproject: the right eye from the left's pixels, holes traced; trace: traced in full (the reference)")
      ->check(CLI::IsMember({"reproject", "trace"}))
      ->capture_default_str();
  app.add_option("--stereo-spread", o.stereo.maxSpread,
                 "A left-eye layer whose content spreads over more than this many pixels of disparity is traced in the right eye (a pixel's front layer spans twice this)")
      ->capture_default_str();
  app.add_option("--stereo-solid", o.stereo.solidAlpha,
                 "A reprojected left-eye pixel at least this opaque hides what lies behind it in the right eye; less opaque ones are "
                 "traced where something may lie behind them")
      ->capture_default_str();
  app.add_option("--tiles", o.tiles,
                 "Bands of rows the frame is cut into, over the renderers in turn, each with its own cache (0: one per GPU of "
                 "--device cuda, else one); balanced every frame by the last frame's times")
      ->capture_default_str()
      ->check(CLI::Range(0, 64));
}

// Parses and checks the values of CliValues into o (a usage error for a bad --size or
// --ground-albedo).
void applyValues(const CLI::App& app, const CliValues& x, canopy::play::PlayOptions& o) {
  int w = 0, h = 0;
  char tail;
  if (std::sscanf(x.size.c_str(), "%dx%d%c", &w, &h, &tail) != 2)
    throw canopy::usageError("--size '" + x.size + "': expected WxH, e.g. 1920x1080");
  o.width = w;
  o.height = h;
  o.shadows = !x.noShadows;
  o.directSun = !x.noDirect;
  if (app.count("--stop-opacity")) o.stopTransmittance = float(1.0 - x.stopOpacity);  // else exactly kStopT
  o.descentCache = !x.noDescentCache;
  o.descentTable = !x.noDescentTable;
  o.skipEmptyBlocks = !x.noEmptySkip;
  o.warmStart = !x.coldStart;
  o.exactLight = x.lightMode == "exact";
  {
    float a[3];
    char tail;
    const int n = std::sscanf(x.groundAlbedo.c_str(), "%f,%f,%f%c", &a[0], &a[1], &a[2], &tail);
    if (n == 1 && std::sscanf(x.groundAlbedo.c_str(), "%f%c", &a[0], &tail) == 1) a[1] = a[2] = a[0];  // one value, nothing after it
    else if (n != 3) throw canopy::usageError("--ground-albedo '" + x.groundAlbedo + "': expected R,G,B or one value in [0, 1]");
    for (int c = 0; c < 3; ++c) o.groundAlbedo[c] = a[c];
  }
}

}  // namespace

int main(int argc, char** argv) {
  canopy::Tool tool("canopy-play",
                    "Cone-traces a packed scene (.canopy) headless, streaming bricks through a cache.\n"
                    "  canopy-play FILE.canopy -o out.png [--size WxH]\n"
                    "  canopy-play FILE.canopy -o frames/f_%04d.exr --frames 120 --camera orbit:turns=1 --sun orbit:turns=0.25\n"
                    "  canopy-play FILE.canopy -o pair.png --stereo 0.064   (left | right)");
  CLI::App& app = tool.app();
  canopy::play::PlayOptions o;
  CliValues x;
  addFrameOptions(app, o, x);
  addShadowOptions(app, o, x);
  addLightOptions(app, o, x);
  addStereoOptions(app, o);
  return tool.run(argc, argv, [&] {
    applyValues(app, x, o);
    tool.report() = canopy::play::play(o, tool.device());
  });
}
