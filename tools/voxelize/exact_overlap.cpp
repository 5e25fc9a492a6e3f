// exact_overlap.cpp: see exact_overlap.h. Epick's predicates are exact on double inputs (interval
// filter, then exact arithmetic when the filter cannot decide).
#include "exact_overlap.h"

#include <CGAL/Exact_predicates_inexact_constructions_kernel.h>
#include <CGAL/intersections.h>

namespace canopy::vox {
namespace {
using K = CGAL::Exact_predicates_inexact_constructions_kernel;
int sgn(CGAL::Orientation o) { return o == CGAL::LEFT_TURN ? 1 : (o == CGAL::RIGHT_TURN ? -1 : 0); }
}  // namespace

void exactNormalSigns(const double a[3], const double b[3], const double c[3], int sign[3]) {
  // n_x: orientation in (y, z); n_y: in (z, x); n_z: in (x, y).
  const int ax[3][2] = {{1, 2}, {2, 0}, {0, 1}};
  for (int k = 0; k < 3; ++k) {
    const int X = ax[k][0], Y = ax[k][1];
    sign[k] = sgn(CGAL::orientation(K::Point_2(a[X], a[Y]), K::Point_2(b[X], b[Y]),
                                    K::Point_2(c[X], c[Y])));
  }
}

bool exactTriBoxOverlap(const double a[3], const double b[3], const double c[3], const double p[3]) {
  const K::Triangle_3 t(K::Point_3(a[0], a[1], a[2]), K::Point_3(b[0], b[1], b[2]),
                        K::Point_3(c[0], c[1], c[2]));
  const CGAL::Bbox_3 box(p[0], p[1], p[2], p[0] + 1, p[1] + 1, p[2] + 1);
  return CGAL::do_intersect(t, box);
}

}  // namespace canopy::vox
