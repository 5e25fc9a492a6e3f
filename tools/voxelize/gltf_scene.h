// gltf_scene.h: a glTF scene whose nodes share meshes as Canopy models + instances. The one place
// that computes them: canopy-voxelize --instances writes the result as a scene list
// (formats/scene_json.h) and canopy-octreepack --scene SCENE.glb packs it directly, so both give
// the same models, names and matrices. No OpenVDB (canopy_mesh_io).
#pragma once
#include <string>

#include "formats/scene_json.h"
#include "mesh_io.h"

namespace canopy::mesh {

// Models: one per glTF mesh that a node of the default scene uses, in ascending mesh index, named
// after the mesh ("mesh<N>" where it has no name), `mesh` set, `density` left empty for the
// caller. Instances: one per such node, in scene traversal order, with the node's name and world
// matrix. `source` is "<file name> xxh64:<hash of the file>" (what canopy-voxelize stamps into the
// lattices it writes). Throws canopy::Error naming the file (unreadable, corrupt, no node with a
// mesh, an instance matrix that checkScene rejects).
Scene sceneFromGltf(const std::string& path);

// The scene list's matrix rule (checkScene: finite, affine, invertible) applied to glTF instances,
// so whole-scene voxelisation refuses the node matrices that --instances refuses, with the same
// message ("<path>: instances[i].matrix is singular"). No instances: nothing to check.
void checkInstanceMatrices(const std::vector<Instance>& instances, const std::string& path);

// Fills every model's density path from `pattern`: {stem} = the glTF file name without its
// extension, {N} = the mesh index, {name} = the mesh name with characters other than [A-Za-z0-9_-]
// replaced by '_'.
void applyModelPattern(Scene& scene, const std::string& gltfPath, const std::string& pattern);

}  // namespace canopy::mesh
