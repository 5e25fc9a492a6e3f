// polygons.h: the mesh Canopy's own polygon readers (ply_loader.cpp, off_loader.cpp) return, built
// in one place: one "default" material without colour; each polygon fanned from its first corner
// (one of fewer than 3 corners gives no triangle); a triangle takes its face's colour where the face
// has one, else the mean of its three corners' vertex colours where the file has them (both 8-bit
// sRGB, made linear), else stays white.
#pragma once
#include <array>
#include <cstdint>
#include <vector>

#include "mesh_io.h"
#include "texture_sample.h"

namespace canopy::mesh {

struct Polygons {
  std::vector<Vec3> points;
  std::vector<std::array<uint8_t, 3>> vertexRgb;  // empty, or one per point
  std::vector<uint32_t> corners;                  // vertex indices (< points.size())
  std::vector<uint32_t> faceStart;                // face f: corners [faceStart[f], faceStart[f + 1]); ends with corners.size()
  std::vector<std::array<uint8_t, 3>> faceRgb;    // empty, or one per face
  std::vector<uint8_t> faceHasRgb;                // with faceRgb: empty = every face has its colour
};

inline Mesh fanPolygons(const Polygons& p) {
  Mesh out;
  Material m;
  m.name = "default";
  m.hasColor = false;
  out.materials.push_back(m);
  const bool vertexColor = !p.vertexRgb.empty();
  bool anyFaceColor = false;
  for (size_t f = 0; f + 1 < p.faceStart.size(); ++f) {
    const bool faceColor = !p.faceRgb.empty() && (p.faceHasRgb.empty() || p.faceHasRgb[f]);
    anyFaceColor |= faceColor;
    const uint32_t b = p.faceStart[f], n = p.faceStart[f + 1] - b;
    for (uint32_t k = 1; k + 1 < n; ++k) {  // fan from the first corner
      Triangle t;
      const uint32_t c[3] = {p.corners[b], p.corners[b + k], p.corners[b + k + 1]};
      for (int v = 0; v < 3; ++v) t.p[size_t(v)] = p.points[c[v]];
      if (faceColor) {
        for (int ch = 0; ch < 3; ++ch) t.color[size_t(ch)] = vox::srgbToLinear8(p.faceRgb[f][size_t(ch)]);
      } else if (vertexColor) {
        t.color = {0, 0, 0};
        for (int v = 0; v < 3; ++v)
          for (int ch = 0; ch < 3; ++ch) t.color[size_t(ch)] += vox::srgbToLinear8(p.vertexRgb[c[v]][size_t(ch)]) / 3.f;
      }
      out.triangles.push_back(t);
    }
  }
  out.hasTriangleColors = vertexColor || anyFaceColor;
  return out;
}

}  // namespace canopy::mesh
