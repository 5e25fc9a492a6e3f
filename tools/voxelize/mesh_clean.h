// mesh_clean.h: removes faces that would distort the density before voxelising.
//
// CGAL does the geometry: Polygon_mesh_processing merges exactly coincident vertices and finds
// duplicate faces (the same three vertices in any order or orientation, e.g. a double-sided leaf
// card modelled twice); CGAL's exact collinearity predicate finds zero-area faces (coincident or
// collinear vertices), which floating-point area tests misjudge for slivers. A duplicate keeps the
// first face in file order (its material and texture coordinates).
#pragma once
#include <cstddef>

#include "mesh_io.h"

namespace canopy::mesh {

struct CleanStats {
  size_t degenerate = 0;  // zero-area faces removed
  size_t duplicate = 0;   // duplicate faces removed
};

// Removes degenerate and duplicate triangles in place; keeps file order of the survivors.
CleanStats removeDegenerateAndDuplicateFaces(Mesh& mesh);

}  // namespace canopy::mesh
