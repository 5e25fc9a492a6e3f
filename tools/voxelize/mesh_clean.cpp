// mesh_clean.cpp: see mesh_clean.h.
#include "mesh_clean.h"

#include <CGAL/Exact_predicates_inexact_constructions_kernel.h>
#include <CGAL/Polygon_mesh_processing/repair_polygon_soup.h>

#include <algorithm>
#include <map>

namespace canopy::mesh {
namespace PMP = CGAL::Polygon_mesh_processing;
using Kernel = CGAL::Exact_predicates_inexact_constructions_kernel;
using Point = Kernel::Point_3;
using Polygon = std::vector<std::size_t>;

CleanStats removeDegenerateAndDuplicateFaces(Mesh& mesh) {
  CleanStats stats;
  const size_t n = mesh.triangles.size();
  // Polygon soup: three points per triangle, merged by PMP where coordinates coincide exactly.
  std::vector<Point> points;
  points.reserve(3 * n);
  std::vector<Polygon> polygons(n);
  for (size_t i = 0; i < n; ++i)
    for (size_t k = 0; k < 3; ++k) {
      const Vec3& p = mesh.triangles[i].p[k];
      polygons[i].push_back(points.size());
      points.emplace_back(p[0], p[1], p[2]);
    }
  PMP::merge_duplicate_points_in_polygon_soup(points, polygons);  // keeps polygon order

  // Zero-area faces: a repeated vertex, or three collinear vertices (exact predicate).
  std::vector<Polygon> kept;
  std::vector<size_t> keptTriangle;
  kept.reserve(n);
  for (size_t i = 0; i < n; ++i) {
    const Polygon& f = polygons[i];
    const bool repeated = f[0] == f[1] || f[1] == f[2] || f[0] == f[2];
    if (repeated || CGAL::collinear(points[f[0]], points[f[1]], points[f[2]])) {
      ++stats.degenerate;
      continue;
    }
    kept.push_back(f);
    keptTriangle.push_back(i);
  }
  // Which surviving face came first, by its (sorted) vertex ids.
  std::map<std::array<size_t, 3>, size_t> first;
  for (size_t j = 0; j < kept.size(); ++j) {
    std::array<size_t, 3> key{kept[j][0], kept[j][1], kept[j][2]};
    std::sort(key.begin(), key.end());
    first.emplace(key, keptTriangle[j]);
  }
  stats.duplicate = PMP::merge_duplicate_polygons_in_polygon_soup(
      points, kept, CGAL::parameters::erase_all_duplicates(false).require_same_orientation(false));

  std::vector<size_t> survivors;
  survivors.reserve(kept.size());
  for (const Polygon& f : kept) {
    std::array<size_t, 3> key{f[0], f[1], f[2]};
    std::sort(key.begin(), key.end());
    survivors.push_back(first.at(key));
  }
  std::sort(survivors.begin(), survivors.end());  // file order
  std::vector<Triangle> out;
  out.reserve(survivors.size());
  for (size_t i : survivors) out.push_back(mesh.triangles[i]);
  mesh.triangles.swap(out);
  return stats;
}

}  // namespace canopy::mesh
