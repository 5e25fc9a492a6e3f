// canopy-voxelize: mesh -> OpenVDB density lattice. Thin main: parse options, call the library.
//
//   canopy-voxelize INPUT -o OUT.vdb [--resolution N] [--supersample S] [--wood-pattern RE]
//                   [--mesh N] [--instances OUT.scene.json [--model-pattern P]] [--no-clean]
//                   [--detail D [--detail-output OUT.detail.vdb]]
//   canopy-voxelize --write-sample OUT.glb
//   canopy-voxelize info FILE.vdb [--json]
#include <algorithm>
#include <cstring>
#include <iostream>

#include "canopy/cli.h"
#include "sample_plant.h"
#include "voxelize.h"

namespace {

int runInfo(int argc, char** argv) {
  canopy::Tool tool("canopy-voxelize info",
                    "Check a Canopy density lattice (.vdb) and print its size, occupancy, total "
                    "density, wood fraction and metadata. Exits 3 if it is not a valid lattice.",
                    false);
  std::string path;
  tool.app().add_option("file", path, "Lattice written by canopy-voxelize")->required();
  return tool.run(argc, argv, [&] {
    nlohmann::json info = canopy::latticeInfo(path);
    if (tool.common().json) {
      tool.report().update(info);
      tool.report()["valid"] = true;
      return;
    }
    const auto& s = info["lattice_size"];
    std::cout << path << ": valid Canopy lattice\n"
              << "  lattice        " << s[0] << " x " << s[1] << " x " << s[2]
              << " (voxel " << info["voxel_size"].get<double>() << " m)\n"
              << "  occupied cells " << info["occupied_cells"] << "\n"
              << "  total density  " << info["total_density"].get<double>() << "\n"
              << "  wood fraction  " << info["wood_fraction"].get<double>() << "\n"
              << "  source         " << info["source"].get<std::string>() << "\n";
    if (info["detail_factor"].get<int>() > 1) {
      const auto &lo = info["light_lattice_min"], &hi = info["light_lattice_max"];
      std::cout << "  detail of      light lattice (" << lo[0] << "," << lo[1] << "," << lo[2] << ")..(" << hi[0]
                << "," << hi[1] << "," << hi[2] << "), " << info["detail_factor"] << " x " << info["detail_factor"]
                << " x " << info["detail_factor"] << " cells per light cell\n";
    }
    for (const auto& g : info["grids"])
      std::cout << "  grid " << g["name"].get<std::string>() << " (" << g["type"].get<std::string>()
                << ", " << g["active_voxels"] << " active)\n";
    for (const auto& [k, v] : info["metadata"].items())
      std::cout << "  meta " << k << " = " << v.get<std::string>() << "\n";
  });
}

// --detail given: 0 is no detail lattice, and refused; without -s, S = max(8, k), so a detail cell
// has S / k >= 1 sub-cells per axis (a factor out of range is left to validateOptions' message).
void detailDefaults(canopy::VoxelizeOptions& o, bool supersampleGiven) {
  if (o.detail == 0) throw canopy::usageError("--detail 0 is not finer than --resolution " + std::to_string(o.resolution));
  if (!supersampleGiven && o.resolution > 0 && o.detail > o.resolution && o.detail / o.resolution <= canopy::kMaxDetailFactor)
    o.supersample = std::max(o.supersample, o.detail / o.resolution);
}

}  // namespace

int main(int argc, char** argv) {
  if (argc >= 2 && std::strcmp(argv[1], "info") == 0) return runInfo(argc - 1, argv + 1);

  canopy::Tool tool("canopy-voxelize",
                    "Voxelise a plant mesh (glTF/glb incl. Draco, OBJ, PLY, STL, OFF) into an "
                    "OpenVDB density lattice with 'density', 'wood' and 'albedo' grids.\n"
                    "Also: 'canopy-voxelize info FILE.vdb [--json]' checks a lattice.");
  canopy::VoxelizeOptions o;
  std::string sample;
  auto& app = tool.app();
  app.add_option("input", o.input, "Input mesh (.glb .gltf .obj .ply .stl .off)");
  app.add_option("-o,--output", o.output, "Output lattice (.vdb)");
  app.add_option("-r,--resolution", o.resolution,
                 "Lattice cells per axis, boundary layer included (" +
                     std::to_string(canopy::kMinResolution) + ".." +
                     std::to_string(canopy::kMaxResolution) + ")")
      ->capture_default_str();
  app.add_option("-s,--supersample", o.supersample,
                 "Fine sub-cells per lattice cell per axis (1.." +
                     std::to_string(canopy::kMaxSupersample) + ")")
      ->capture_default_str();
  app.add_option("--wood-pattern", o.woodPattern,
                 "Materials whose name matches this regex (case-insensitive) are wood")
      ->capture_default_str();
  app.add_option("--mesh", o.meshIndex,
                 "glTF: voxelise mesh N alone in its own model space (default: the whole scene "
                 "with node transforms)")
      ->check(CLI::Validator(
          [](std::string& v) {
            // -1 is the library's "whole scene", not a value a user may give.
            return v.find_first_not_of("0123456789") == std::string::npos ? std::string()
                                                                           : "must be a mesh index >= 0, got " + v;
          },
          "N >= 0"));
  app.add_option("--instances", o.instancesOutput,
                 "glTF: also write the scene instance list (docs/scene-json.md) to this file");
  app.add_option("--model-pattern", o.modelPattern,
                 "Density path of each model in the instance list; {stem} {N} {name} are replaced")
      ->capture_default_str();
  bool noClean = false;
  app.add_flag("--no-clean", noClean, "Keep degenerate and duplicate faces");
  auto* detail = app.add_option("--detail", o.detail,
                                "Also write a finer detail lattice of D = resolution x 2, 4, 8 or 16 cells per "
                                "axis, nested in the lattice (default supersample: max(8, D / resolution))");
  app.add_option("--detail-output", o.detailOutput,
                 "The detail lattice (.vdb; default: -o with .density.vdb replaced by .detail.vdb)");
  app.add_option("--write-sample", sample,
                 "Write Canopy's built-in procedural sample plant (.glb) and exit");

  return tool.run(argc, argv, [&] {
    o.clean = !noClean;
    if (detail->count() > 0) detailDefaults(o, app.count("--supersample") > 0);
    // Voxelisation runs on CPU cores (TBB); an explicit GPU request is refused, not ignored.
    if (tool.common().device.rfind("cuda", 0) == 0)
      throw canopy::unsupported("canopy-voxelize runs on the CPU only (--device cpu or auto)");
    tool.device();  // validates the spelling
    if (!sample.empty()) {
      canopy::writeSamplePlant(sample);
      tool.report()["sample"] = sample;
      canopy::logInfo("canopy-voxelize: wrote sample plant " + sample);
      return;
    }
    if (o.input.empty()) throw canopy::usageError("no input mesh given");
    if (o.output.empty() && o.instancesOutput.empty())
      throw canopy::usageError("no output given (-o OUT.vdb and/or --instances OUT.scene.json)");
    if (o.output.empty()) {
      // Only the scene list: no voxelisation.
      canopy::validateOptions(o);
      if (o.detail != 0) throw canopy::usageError("--detail needs -o OUT.density.vdb (the lattice it nests in)");
      canopy::writeInstances(o.input, o.instancesOutput, o.modelPattern);
      tool.report()["input"] = o.input;
      tool.report()["instances"] = o.instancesOutput;
      return;
    }
    canopy::voxelize(o, &tool.report());
  });
}
