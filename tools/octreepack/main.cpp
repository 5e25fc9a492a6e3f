// main.cpp: canopy-octreepack's command line (pack, info, verify); the work is in octreepack.cpp.
#include <iostream>

#include "canopy/cli.h"
#include "tools/octreepack/octreepack.h"

int main(int argc, char** argv) {
  canopy::Tool tool("canopy-octreepack",
                    "Packs density lattices (and scene instances) into one streamable .canopy file.\n"
                    "  canopy-octreepack PLANT.density.vdb [PLANT.light.chaar|PLANT.light.vdb] -o PLANT.canopy\n"
                    "  canopy-octreepack PLANT.detail.vdb PLANT.light.chaar -o PLANT.canopy   (a detail lattice of\n"
                    "    canopy-voxelize --detail, lit from the lattice it nests in)\n"
                    "  canopy-octreepack --scene SCENE.json -o SCENE.canopy\n"
                    "  canopy-octreepack --scene SCENE.glb MESH.density.vdb [MESH.light.chaar] ... -o SCENE.canopy\n"
                    "    (one lattice per mesh the scene uses, from canopy-voxelize SCENE.glb --mesh N; matched to\n"
                    "     its mesh by the lattice's metadata, in any order; lighting follows its lattice)\n"
                    "  canopy-octreepack info FILE.canopy [--json]\n"
                    "  canopy-octreepack verify FILE.canopy [--json]",
                    /*withDevice=*/false);
  CLI::App& app = tool.app();
  canopy::octreepack::OctreepackOptions o;
  app.add_option("inputs", o.inputs,
                 "PLANT.density.vdb [PLANT.light.chaar | PLANT.light.vdb]; with --scene SCENE.glb, one such "
                 "pair per mesh of the scene");
  app.add_option("-o,--output", o.output, "Output .canopy file");
  app.add_option("--scene", o.scene,
                 "Scene: an instance list (SCENE.json, docs/scene-json.md) or a glTF scene whose nodes share "
                 "meshes (SCENE.glb/.gltf, with the meshes' lattices as inputs)");
  app.add_option("--scene-light", o.sceneLight,
                 "Coarse scene lighting lattice (VDB of canopy-lbsolve --scene): its 19 bases B00..B18 are packed (the player "
                 "weights each instance's scattered sun by the sun's bases, its ambient light by B00)");
  app.add_option("--scene-light-grid", o.sceneLightGrid,
                 "Pack only this float grid of --scene-light, as the one factor of all indirect light (a static scene light, "
                 "as before format 1.2; e.g. B00)");
  app.add_flag("--ignore-light", o.ignoreLight, "Pack density only, even where a .chaar is given");
  app.add_flag("--no-haar-light", o.noHaarLight,
               "Pack a .chaar's lighting as light items only, without its Haar bricks (the finest level's exact light: "
               "canopy-play --light exact); a smaller file");
  app.add_option("--pages", o.pageCoding,
                 "zstd: every page compressed on its own (format 5.0; a lit detail plant takes half the bytes, pages decompress "
                 "as they stream); raw: page images as before 5.0, for older readers")
      ->check(CLI::IsMember({"zstd", "raw"}))
      ->capture_default_str();
  app.add_option("--zstd-level", o.zstdLevel, "Zstandard level of --pages zstd (higher: smaller and slower to pack; the same speed to read)")
      ->check(CLI::Range(1, 19))
      ->capture_default_str();
  app.fallthrough();  // (inherited by the subcommands) `info FILE --json` works too
  std::string infoPath, verifyPath;
  CLI::App* info = app.add_subcommand("info", "Print models, levels, node/brick/page counts and bytes per section");
  info->add_option("file", infoPath, "FILE.canopy")->required();
  CLI::App* verify = app.add_subcommand("verify", "Check every checksum and pointer; exit non-zero on any problem");
  verify->add_option("file", verifyPath, "FILE.canopy")->required();
  app.require_subcommand(0, 1);

  return tool.run(argc, argv, [&] {
    namespace op = canopy::octreepack;
    if (*info) {
      nlohmann::json j = op::canopyInfo(canopy::CanopyFile::open(infoPath));
      if (tool.common().json) tool.report() = j;
      else std::cout << op::formatInfo(j);
    } else if (*verify) {
      try {
        op::canopyVerify(verifyPath, tool.report());
      } catch (const canopy::Error&) {
        tool.report()["ok"] = false;
        throw;
      }
      if (!tool.common().json) std::cout << verifyPath << ": ok (" << tool.report()["pages_checked"].dump() << " pages)\n";
    } else {
      tool.report() = op::octreepack(o);
    }
  });
}
