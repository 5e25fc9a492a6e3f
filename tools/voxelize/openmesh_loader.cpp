// openmesh_loader.cpp: OBJ, STL and OFF through OpenMesh, and loadMesh()'s format dispatch (PLY
// goes to Canopy's own reader, ply_loader.cpp).
//
// OpenMesh reads the geometry (polygons are triangulated as fans) and face or vertex colours where
// the format has them. It does not keep OBJ material names, which Canopy needs to tell wood from
// leaves, so scanObjMaterials() reads the `usemtl` runs and, when OpenMesh produced exactly the
// triangles those runs predict (the usual case), assigns each triangle its material by order.
// OpenMesh silently drops vertices or facets with NaN coordinates (OBJ, OFF, binary and ASCII
// STL), so those files are scanned for non-finite coordinates before OpenMesh reads them.
#include <OpenMesh/Core/IO/MeshIO.hh>
#include <OpenMesh/Core/Mesh/TriMesh_ArrayKernelT.hh>

#include <algorithm>
#include <cstdlib>
#include <cmath>
#include <cstring>
#include <fstream>
#include <map>
#include <sstream>

#include "canopy/atomic_file.h"
#include "canopy/cli.h"
#include "canopy/errors.h"
#include "mesh_io.h"
#include "texture_sample.h"

namespace canopy::mesh {
namespace {

struct OmTraits : OpenMesh::DefaultTraits {
  using Point = OpenMesh::Vec3d;
  VertexAttributes(OpenMesh::Attributes::Color);
  FaceAttributes(OpenMesh::Attributes::Color);
};
using OmMesh = OpenMesh::TriMesh_ArrayKernelT<OmTraits>;

// Material runs of an OBJ file: for each `f` line, the material index and triangle count.
struct ObjMaterials {
  std::vector<std::string> names;        // in order of first use; [0] = "default"
  std::vector<int> triangleMaterial;     // one per predicted triangle
  long nonFiniteVertex = -1;             // 1-based index of the first `v` with NaN/inf, or -1
};

ObjMaterials scanObjMaterials(const std::string& path) {
  ObjMaterials m;
  m.names.push_back("default");
  std::map<std::string, int> index{{"default", 0}};
  int current = 0;
  long vertices = 0;
  std::ifstream in(path);
  std::string line;
  while (std::getline(in, line)) {
    if (line.size() < 2) continue;
    if (line[0] == 'v' && (line[1] == ' ' || line[1] == '\t')) {
      // OpenMesh silently drops vertices it cannot parse ("nan", "inf"): catch them here.
      ++vertices;
      const char* p = line.c_str() + 2;
      for (int k = 0; k < 3 && m.nonFiniteVertex < 0; ++k) {
        char* end = nullptr;
        const double v = std::strtod(p, &end);
        if (end == p) break;
        if (!std::isfinite(v)) m.nonFiniteVertex = vertices;
        p = end;
      }
      continue;
    }
    if (line.compare(0, 7, "usemtl ") == 0) {
      std::string n = line.substr(7);
      while (!n.empty() && (n.back() == '\r' || n.back() == ' ')) n.pop_back();
      auto [it, added] = index.emplace(n, int(m.names.size()));
      if (added) m.names.push_back(n);
      current = it->second;
    } else if (line[0] == 'f' && (line[1] == ' ' || line[1] == '\t')) {
      std::istringstream ss(line.substr(2));
      std::string tok;
      int corners = 0;
      while (ss >> tok) ++corners;
      for (int t = 0; t + 2 < corners; ++t) m.triangleMaterial.push_back(current);
    }
  }
  return m;
}

// A binary STL (84 + 50 n bytes): the 0-based facet with a non-finite corner, or -1.
long nonFiniteBinaryStlFacet(const std::vector<unsigned char>& b) {
  if (b.size() < 84) return -1;
  uint32_t n;
  std::memcpy(&n, b.data() + 80, 4);
  if (b.size() != 84 + 50 * uint64_t(n)) return -1;
  for (uint32_t i = 0; i < n; ++i)
    for (int k = 0; k < 9; ++k) {
      float v;
      std::memcpy(&v, b.data() + 84 + 50 * size_t(i) + 12 + 4 * size_t(k), 4);
      if (!std::isfinite(v)) return long(i);
    }
  return -1;
}

// An ASCII STL: the 0-based facet whose `vertex` line has a non-finite number, or -1.
long nonFiniteAsciiStlFacet(const std::vector<unsigned char>& b) {
  std::istringstream in(std::string(b.begin(), b.end()));
  long facet = -1;
  for (std::string tok; in >> tok;) {
    if (tok == "facet") ++facet;
    if (tok != "vertex") continue;
    for (int k = 0; k < 3 && in >> tok; ++k) {
      char* end = nullptr;
      const double v = std::strtod(tok.c_str(), &end);
      if (end != tok.c_str() && !std::isfinite(v)) return std::max(facet, 0L);
    }
  }
  return -1;
}

// An ASCII OFF (any of the [ST][C][N]OFF headers): the 0-based vertex with a non-finite
// coordinate, or -1. Binary and 4-D OFF are left to OpenMesh.
long nonFiniteOffVertex(const std::string& path) {
  std::ifstream in(path);
  std::string line;
  auto next = [&](std::vector<std::string>& t) {
    while (std::getline(in, line)) {
      if (const auto hash = line.find('#'); hash != std::string::npos) line.erase(hash);
      std::istringstream ss(line);
      t.clear();
      for (std::string s; ss >> s;) t.push_back(s);
      if (!t.empty()) return true;
    }
    return false;
  };
  std::vector<std::string> t;
  if (!next(t)) return -1;
  const std::string& key = t[0];
  if (key.size() < 3 || key.compare(key.size() - 3, 3, "OFF") != 0 || key.find_first_of("4n") != std::string::npos)
    return -1;
  if (t.size() > 1 && t[1] == "BINARY") return -1;
  std::vector<std::string> counts(t.begin() + 1, t.end());
  if (counts.empty() && !next(counts)) return -1;
  char* end = nullptr;
  const long nv = std::strtol(counts[0].c_str(), &end, 10);
  for (long v = 0; v < nv && next(t); ++v)
    for (size_t k = 0; k < 3 && k < t.size(); ++k) {
      const double x = std::strtod(t[k].c_str(), &end);
      if (end != t[k].c_str() && !std::isfinite(x)) return v;
    }
  return -1;
}

}  // namespace

std::string extensionOf(const std::string& path) {
  const auto slash = path.find_last_of('/');
  const auto dot = path.find_last_of('.');
  if (dot == std::string::npos || (slash != std::string::npos && dot < slash)) return "";
  std::string e = path.substr(dot + 1);
  std::transform(e.begin(), e.end(), e.begin(), [](unsigned char c) { return char(std::tolower(c)); });
  return e;
}

Error nonFiniteTriangle(const std::string& name, size_t index) {
  return invalidInput(name + ": triangle " + std::to_string(index) + " has a NaN or infinite vertex coordinate");
}

void requireFinite(const Mesh& mesh, const std::string& name) {
  for (size_t i = 0; i < mesh.triangles.size(); ++i)
    for (const Vec3& p : mesh.triangles[i].p)
      for (double c : p)
        if (!std::isfinite(c)) throw nonFiniteTriangle(name, i);
}

Mesh loadWithOpenMesh(const std::string& path) {
  const std::string ext = extensionOf(path);
  if (ext == "ply") return loadPly(path);  // never OpenMesh's PLY reader (it hangs on truncation)
  requireReadableFile(path);
  {
    std::ifstream probe(path, std::ios::binary | std::ios::ate);
    if (probe.tellg() == 0) throw invalidInput(path + ": empty file");
  }
  if (ext == "stl") {
    const std::vector<unsigned char> bytes = readFile(path);
    long facet = nonFiniteBinaryStlFacet(bytes);
    if (facet < 0) facet = nonFiniteAsciiStlFacet(bytes);
    if (facet >= 0) throw nonFiniteTriangle(path, size_t(facet));
  } else if (ext == "off") {
    if (const long v = nonFiniteOffVertex(path); v >= 0)
      throw invalidInput(path + ": vertex " + std::to_string(v) + " (counting from 0) has a NaN or infinite coordinate");
  }
  omerr().disable();
  omlog().disable();
  omout().disable();
  OmMesh om;
  om.request_vertex_colors();
  om.request_face_colors();
  OpenMesh::IO::Options opt = OpenMesh::IO::Options::VertexColor | OpenMesh::IO::Options::FaceColor;
  if (!OpenMesh::IO::read_mesh(om, path, opt))
    throw invalidInput(path + ": OpenMesh could not parse the file (malformed or truncated)");

  Mesh out;
  ObjMaterials objMat;
  bool byOrder = false;
  if (ext == "obj") {
    objMat = scanObjMaterials(path);
    if (objMat.nonFiniteVertex > 0)
      throw invalidInput(path + ": vertex " + std::to_string(objMat.nonFiniteVertex) +
                         " has a NaN or infinite coordinate");
    byOrder = objMat.triangleMaterial.size() == om.n_faces();
    if (!byOrder && objMat.names.size() > 1)
      logWarn(path + ": OBJ material runs do not match the faces OpenMesh read; materials ignored");
  }
  if (byOrder) {
    for (const auto& n : objMat.names) {
      Material m;
      m.name = n;
      m.hasColor = false;
      out.materials.push_back(m);
    }
  } else {
    Material m;
    m.name = "default";
    m.hasColor = false;
    out.materials.push_back(m);
  }
  const bool faceColor = opt.face_has_color();
  const bool vertexColor = opt.vertex_has_color();
  out.hasTriangleColors = faceColor || vertexColor;
  out.triangles.reserve(om.n_faces());
  size_t fi = 0;
  for (auto f : om.faces()) {
    Triangle t;
    int k = 0;
    std::array<float, 3> vc{0, 0, 0};
    for (auto v : om.fv_range(f)) {
      if (k == 3) break;
      const auto& p = om.point(v);
      t.p[size_t(k)] = {p[0], p[1], p[2]};
      if (vertexColor) {
        const auto c = om.color(v);
        for (int ch = 0; ch < 3; ++ch) vc[size_t(ch)] += vox::srgbToLinear8(c[ch]) / 3.f;
      }
      ++k;
    }
    if (k != 3) continue;
    if (faceColor) {
      const auto c = om.color(f);
      for (int ch = 0; ch < 3; ++ch) t.color[size_t(ch)] = vox::srgbToLinear8(c[ch]);
    } else if (vertexColor) {
      t.color = vc;
    }
    t.material = byOrder ? objMat.triangleMaterial[fi] : 0;
    out.triangles.push_back(t);
    ++fi;
  }
  return out;
}

Mesh loadMesh(const std::string& path, const LoadOptions& options) {
  requireReadableFile(path);
  const std::string ext = extensionOf(path);
  Mesh mesh;
  if (ext == "glb" || ext == "gltf") {
    mesh = loadGltfFile(path, options);
  } else if (ext == "obj" || ext == "ply" || ext == "stl" || ext == "off") {
    if (options.meshIndex >= 0) throw usageError(path + ": --mesh applies to glTF files only");
    mesh = loadWithOpenMesh(path);
  } else {
    throw unsupported(path + ": unknown mesh format '" + ext +
                      "' (expected .glb, .gltf, .obj, .ply, .stl or .off)");
  }
  requireFinite(mesh, path);
  return mesh;
}

}  // namespace canopy::mesh
