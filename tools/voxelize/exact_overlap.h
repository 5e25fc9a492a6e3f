// exact_overlap.h: the exact predicates behind overlap.h's fast test (CGAL, host only).
#pragma once

namespace canopy::vox {

// Exact signs (-1, 0, 1) of the components of (b - a) x (c - a): the orientations of the yz, zx
// and xy projections of the triangle.
void exactNormalSigns(const double a[3], const double b[3], const double c[3], int sign[3]);

// Exact: does the closed triangle abc meet the closed box [p, p+1]^3?
bool exactTriBoxOverlap(const double a[3], const double b[3], const double c[3], const double p[3]);

}  // namespace canopy::vox
