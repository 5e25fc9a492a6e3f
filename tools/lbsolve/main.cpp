// canopy-lbsolve: lattice-Boltzmann lighting of a density lattice (see lbsolve.h, docs/lbsolve.md).
//   canopy-lbsolve IN.density.vdb -o OUT.light.vdb [--params P.json] [--sun x,y,z] ...
//   canopy-lbsolve --scene SCENE.json -o OUT.scene-light.vdb [--scene-resolution N]
//   canopy-lbsolve info FILE.light.vdb [--json]
#include <cstring>
#include <iostream>

#include "canopy/cli.h"
#include "lbsolve.h"

namespace {

int runInfo(int argc, char** argv) {
  canopy::Tool tool("canopy-lbsolve info", "Checks and describes a light file written by canopy-lbsolve.", false);
  std::string path;
  tool.app().add_option("file", path, "Light file (.vdb)")->required();
  return tool.run(argc - 1, argv + 1, [&] {
    const canopy::LightFileInfo info = canopy::inspectLightFile(path);
    tool.report() = info.toJson();
    if (tool.common().json) return;
    std::cout << path << ": " << info.kind << " light file, lattice (" << info.latticeMin[0] << ","
              << info.latticeMin[1] << "," << info.latticeMin[2] << ")..(" << info.latticeMax[0] << ","
              << info.latticeMax[1] << "," << info.latticeMax[2] << "), " << info.activeVoxels
              << " stored nodes\ngrids:";
    for (const auto& g : info.grids) std::cout << ' ' << g;
    std::cout << '\n';
    for (auto it = info.metadata.begin(); it != info.metadata.end(); ++it)
      std::cout << it.key() << ": " << (it->is_string() ? it->get<std::string>() : it->dump()) << '\n';
  });
}

}  // namespace

int main(int argc, char** argv) {
  if (argc > 1 && std::strcmp(argv[1], "info") == 0) return runInfo(argc, argv);

  canopy::Tool tool("canopy-lbsolve",
                    "Lattice-Boltzmann lighting: 19 base solutions (or one sun) for a density lattice.\n"
                    "Also: 'canopy-lbsolve info FILE.vdb [--json]' checks and describes a light file.");
  canopy::LbsolveOptions o;
  std::vector<float> sun;
  double woodThreshold = -1;
  auto& app = tool.app();
  app.add_option("input", o.input, "Density lattice from canopy-voxelize (.vdb)");
  app.add_option("-o,--output", o.output, "Output light file (.vdb)")->required();
  app.add_option("--params", o.paramsFile, "JSON parameter file (sigma_a, sigma_s, fs/bs or g, wood_g, wood_threshold, sigma, collision)");
  app.add_option("--sun", sun, "One static solution for this sun: the direction light travels, x,y,z")
      ->delimiter(',')->expected(3);
  app.add_option("--ambient", o.ambient, "With --sun: ambient boundary value on all 19 directions")->capture_default_str();
  app.add_option("--iterations", o.iterations, "Iteration cap (0 = 2 x the longest lattice edge)")->capture_default_str();
  app.add_option("--tolerance", o.tolerance, "Stop when the largest change of the node totals per iteration, relative to their maximum, is <= this; 0 = run exactly --iterations")
      ->capture_default_str();
  app.add_option("--check-every", o.checkEvery, "Residual check interval (iterations)")->capture_default_str();
  app.add_option("--wood-threshold", woodThreshold, "Wood fraction at or above which a node is wood (default 0.5 or the parameter file's)");
  double sigma = 0;
  app.add_option("--sigma", sigma,
                 "Extinction per lattice cell at density 1 (default 4 or the parameter file's): the medium of "
                 "canopy-play --sigma, so that the light solved here and the player's shadows agree");
  std::string collision;
  app.add_option("--collision", collision,
                 "How density becomes interaction: beer-lambert (p = 1 - exp(-sigma rho |c|), default) or linear "
                 "(p = rho, the dissertation's collision)")
      ->check(CLI::IsMember({"beer-lambert", "linear"}));
  app.add_option("--cuda-scheme", o.cudaScheme,
                 "CUDA streaming scheme: shift (index shift, work at occupied nodes only), shift-split, push "
                 "(listing 5.2 over every node) or pull (every node, aligned stores in tiles of 32 nodes); all give the CPU's bits")
      ->capture_default_str();
  app.add_option("--solves-per-gpu", o.solvesPerGpu,
                 "CUDA: solves in flight on each GPU (own stream and buffers; fewer where memory is short); "
                 "the results do not depend on it")
      ->capture_default_str();
  std::string sunBases = "scattered";
  app.add_option("--sun-bases", sunBases,
                 "Sun bases B01..B18: scattered (the direct beam removed; the player adds its own shadowed direct sun) "
                 "or total (beam included, the dissertation's B_j)")
      ->check(CLI::IsMember({"scattered", "total"}))
      ->capture_default_str();
  app.add_option("--scene", o.scene, "Scene instance list (docs/scene-json.md): solve the coarse scene-level lattice instead");
  app.add_option("--scene-resolution", o.sceneResolution, "Scene mode: coarse cells along the scene's longest axis")
      ->capture_default_str();

  return tool.run(argc, argv, [&] {
    o.scatteredSunBases = sunBases == "scattered";
    if (app.count("--sun-bases") && (!sun.empty() || !o.scene.empty()))
      throw canopy::usageError("--sun-bases applies to the 19 bases, not to --sun or --scene");
    if (!sun.empty()) o.sun = std::array<float, 3>{sun[0], sun[1], sun[2]};
    if (app.count("--wood-threshold")) {  // a command-line value: usage (1); a --params file's: invalid input (3)
      if (!canopy::lb::woodThresholdInRange(woodThreshold)) throw canopy::usageError("--wood-threshold must lie in [0, 1]");
      o.woodThreshold = woodThreshold;
    }
    if (app.count("--sigma")) {
      if (!canopy::lb::sigmaInRange(sigma)) throw canopy::usageError("--sigma must lie in (0, 64]");
      o.sigma = sigma;
    }
    if (app.count("--collision")) o.beerLambert = collision == "beer-lambert";
    if (!o.scene.empty() && (app.count("--sigma") || app.count("--collision")))
      throw canopy::usageError("--sigma and --collision apply to a plant's lattice, not to --scene (its coarse lattice uses the linear collision)");
    if (!o.scene.empty() && !o.input.empty()) throw canopy::usageError("give either an input lattice or --scene, not both");
    o.device = tool.device();
    const canopy::LbsolveReport r = canopy::lbsolve(o);
    tool.report() = r.toJson();
    tool.report()["output"] = o.output;
    canopy::logInfo("wrote " + o.output + " (" + std::to_string(r.solves.size()) + " solves, " +
                    std::to_string(r.nodeUpdates) + " node updates, " + std::to_string(r.seconds) + " s)");
  });
}
