// bench-reference: canopy-play's image against the Monte Carlo reference of the same medium
// (tests/reference/pathtrace.h, docs/validation.md) for a plant and a 3-tree scene under a low
// and a high sun, at more samples per pixel than test_reference; prints a Markdown table.
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>
#include <vector>

#include "bench/bench_usage.h"
#include "tests/reference/compare.h"

namespace {

const char* kUsage =
    "usage: bench-reference [--mesh PLANT.glb] [--resolution N] [--size N] [--spp N] [--seed S]\n"
    "                       [--shadows map|cone|both] [--elevations LOW,HIGH] [--two-seeds] [--indirect-sigma S]\n"
    "                       [--shadow-map-bias B]\n"
    "                       [--work DIR] [--images DIR]\n"
    "  Runs voxelize (N^3, default 40, at most 48) -> lbsolve -> octreepack in-process on the plant\n"
    "  (default ../shared/assets/plants/oak_medium.glb) and on a 3-tree scene of it, renders each with\n"
    "  canopy-play's CPU renderer and with the Monte Carlo path tracer (size^2 pixels, default 128,\n"
    "  at most 128; --spp paths per pixel, default 256) under a low and a high sun (default 15,70\n"
    "  degrees), and prints a Markdown table: image RMS / mean, MC noise, alpha RMS, mean ratio,\n"
    "  times; each case also direct sun only (the player on the unlit file with --ambient 0, the\n"
    "  reference's single scattering) and indirect light only (--no-direct-sun; the reference without\n"
    "  the camera vertex's sun). --indirect-sigma S adds an indirect row whose reference light field\n"
    "  (every path segment after the camera vertex) is traced with extinction S instead of --sigma's 4:\n"
    "  S = 1 is the medium lbsolve's linear collision solves (a diagnostic).\n"
    "  --shadow-map-bias B plays the map rows with canopy-play --shadow-map-bias B (blur widths).\n"
    "  --two-seeds traces each case again with seed S+1 and reports the noise measured from\n"
    "  the two images too. --images DIR writes CASE.mc.exr/.png and CASE.play.exr/.png there.\n";

}  // namespace

int main(int argc, char** argv) {
  if (benchHelpRequested(argc, argv, kUsage)) return 0;
  std::string mesh = std::string(CANOPY_SOURCE_DIR) + "/../shared/assets/plants/oak_medium.glb";
  std::string work = "bench-reference-work", images, shadows = "map";
  int resolution = 40, size = 128, spp = 256;
  unsigned long long seed = 1;
  double low = 15.0, high = 70.0;
  bool twoSeeds = false;
  float indirectSigma = 0.0f, shadowMapBias = -1.0f;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (a == "--two-seeds") {
      twoSeeds = true;
      continue;
    }
    if (i + 1 >= argc) return benchUsageError("bench-reference", ("missing value after " + a).c_str(), kUsage);
    const char* v = argv[++i];
    if (a == "--mesh") mesh = v;
    else if (a == "--resolution") resolution = std::atoi(v);
    else if (a == "--size") size = std::atoi(v);
    else if (a == "--spp") spp = std::atoi(v);
    else if (a == "--seed") seed = std::strtoull(v, nullptr, 10);
    else if (a == "--shadows") shadows = v;
    else if (a == "--work") work = v;
    else if (a == "--images") images = v;
    else if (a == "--indirect-sigma") indirectSigma = float(std::atof(v));
    else if (a == "--shadow-map-bias") shadowMapBias = float(std::atof(v));
    else if (a == "--elevations") {
      if (std::sscanf(v, "%lf,%lf", &low, &high) != 2) return benchUsageError("bench-reference", "--elevations LOW,HIGH", kUsage);
    } else {
      --i;
      return benchUsageError("bench-reference", ("unknown option " + a).c_str(), kUsage);
    }
  }
  if (resolution < 8 || resolution > 48 || size < 1 || size > 128 || spp < 2 || spp > canopy::reference::kMaxSpp)
    return benchUsageError("bench-reference", "--resolution must be 8..48, --size 1..128, --spp 2..4096", kUsage);
  if (!(indirectSigma >= 0.0f && indirectSigma < 1e6f)) return benchUsageError("bench-reference", "--indirect-sigma must be >= 0", kUsage);
  if (shadows != "map" && shadows != "cone" && shadows != "both") return benchUsageError("bench-reference", "--shadows map|cone|both", kUsage);
  try {
    namespace ref = canopy::reference;
    ref::PrepareOptions po;
    po.mesh = mesh;
    po.workDir = work;
    po.resolution = resolution;
    const ref::Prepared p = ref::prepareScenes(po);
    if (!images.empty()) {
      const std::string cmd = "mkdir -p '" + images + "'";
      if (std::system(cmd.c_str()) != 0) return 2;
    }
    std::printf("pipeline on %s at %d^3 (voxelize, lbsolve, octreepack x2): %.1f s\n\n", mesh.c_str(), resolution, p.seconds);
    std::printf("| scene | sun elev. | light | shadows | pixels | spp | RMS / mean | MC noise | MC noise (2 seeds) | alpha RMS | mean play | mean MC | mean play/MC | player s | MC s |\n");
    std::printf("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n");
    std::vector<std::string> methods = shadows == "both" ? std::vector<std::string>{"map", "cone"} : std::vector<std::string>{shadows};
    for (const ref::PreparedScene* s : {&p.plant, &p.trees})
      for (double elev : {low, high})
        for (int light = 0; light < 4; ++light)  // full, direct sun only, indirect only, indirect in the LB's medium
        for (const std::string& m : methods) {
          if (light >= 2 && m != methods.front()) continue;  // no direct sun: no shadows either
          if (light == 3 && !(indirectSigma > 0.0f)) continue;
          const bool direct = light == 1;
          ref::CaseOptions o;
          o.directOnly = direct;
          o.indirectOnly = light >= 2;
          if (light == 3) o.trace.indirectSigma = indirectSigma;
          o.width = o.height = size;
          o.sunElevation = elev;
          o.shadows = m;
          if (shadowMapBias >= 0.0f) o.tweakPlayer = [shadowMapBias](canopy::play::PlayOptions& po) { po.shadowMapBias = shadowMapBias; };
          o.trace.spp = spp;
          o.trace.seed = seed;
          if (twoSeeds) o.secondSeed = seed + 1;
          if (!images.empty()) {
            char name[256];
            std::snprintf(name, sizeof name, "%s/%s-sun%g-%s%s", images.c_str(), s == &p.plant ? "plant" : "trees", elev, m.c_str(),
                          light == 1 ? "-direct" : light == 2 ? "-indirect" : light == 3 ? "-indirect-lbmedium" : "");
            o.exrPrefix = name;
          }
          const ref::CaseResult r = ref::compareCase(*s, o);
          char two[32] = "-", lightName[64];
          std::snprintf(lightName, sizeof lightName, "indirect, MC field sigma %g", double(indirectSigma));
          if (r.noiseTwoSeeds >= 0) std::snprintf(two, sizeof two, "%.4f", r.noiseTwoSeeds);
          std::printf("| %s | %g | %s | %s | %dx%d | %d | %.4f | %.4f | %s | %.4f | %.5f | %.5f | %.4f | %.2f | %.1f |\n", s->name.c_str(),
                      elev, light == 0 ? "full" : light == 1 ? "direct sun" : light == 2 ? "indirect" : lightName, light >= 2 ? "-" : m.c_str(), size, size, spp, r.rms, r.noise, two, r.alphaRms, r.meanPlay, r.meanMc,
                      r.meanRatio, r.playSeconds, r.mcSeconds);
          std::fflush(stdout);
        }
  } catch (const std::exception& e) {
    std::fprintf(stderr, "bench-reference: %s\n", e.what());
    return 2;
  }
  return 0;
}
