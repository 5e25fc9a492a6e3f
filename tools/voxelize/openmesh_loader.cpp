// openmesh_loader.cpp: OBJ and STL through OpenMesh, and loadMesh()'s format dispatch (PLY and
// OFF go to Canopy's own readers, ply_loader.cpp and off_loader.cpp).
//
// OpenMesh reads the geometry (polygons are triangulated as fans) and face or vertex colours where
// the format has them. It does not keep OBJ material names, which Canopy needs to tell wood from
// leaves, so scanObjMaterials() reads the `usemtl` runs and, when OpenMesh produced exactly the
// triangles those runs predict (the usual case), assigns each triangle its material by order.
// OpenMesh silently drops what it cannot use (vertices or facets with NaN coordinates, OBJ faces
// with bad indices) and reads a truncated STL as far as it goes, so OBJ and STL files are checked
// here before OpenMesh reads them.
#include <OpenMesh/Core/IO/MeshIO.hh>
#include <OpenMesh/Core/Mesh/TriMesh_ArrayKernelT.hh>

#include <algorithm>
#include <cctype>
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
};

// Reads an OBJ's `v`, `f` and `usemtl` lines before OpenMesh does, which silently drops what it
// cannot use: vertices with NaN/inf coordinates (refused here) and faces whose vertex index is 0,
// out of range or fewer than three (refused here, with the line).
ObjMaterials scanObjMaterials(const std::string& path) {
  ObjMaterials m;
  m.names.push_back("default");
  std::map<std::string, int> index{{"default", 0}};
  int current = 0;
  long vertices = 0;
  long lineNo = 0;
  long long maxIndex = 0;
  long maxIndexLine = 0;  // the largest positive index (checked at the end)
  std::ifstream in(path);
  std::string line;
  auto at = [&] { return path + ": line " + std::to_string(lineNo) + ": "; };
  while (std::getline(in, line)) {
    ++lineNo;
    // as OpenMesh reads a line: leading whitespace skipped, '#' to the end a comment
    if (const auto hash = line.find('#'); hash != std::string::npos) line.erase(hash);
    line.erase(0, std::min(line.size(), line.find_first_not_of(" \t\r\f\v")));
    if (line.size() < 2) continue;
    if (line[0] == 'v' && (line[1] == ' ' || line[1] == '\t')) {
      ++vertices;
      const char* p = line.c_str() + 2;
      for (int k = 0; k < 3; ++k) {
        char* end = nullptr;
        const double v = std::strtod(p, &end);
        if (end == p) break;
        if (!std::isfinite(v))
          throw invalidInput(path + ": vertex " + std::to_string(vertices) + " has a NaN or infinite coordinate");
        p = end;
      }
      continue;
    }
    if (line.compare(0, 7, "usemtl ") == 0) {
      std::string n = line.substr(7);
      while (!n.empty() && (n.back() == '\r' || n.back() == ' ' || n.back() == '\t')) n.pop_back();
      auto [it, added] = index.emplace(n, int(m.names.size()));
      if (added) m.names.push_back(n);
      current = it->second;
    } else if (line[0] == 'f' && (line[1] == ' ' || line[1] == '\t')) {
      std::istringstream ss(line.substr(2));
      std::string tok;
      int corners = 0;
      while (ss >> tok) {
        ++corners;
        char* end = nullptr;
        const long long v = std::strtoll(tok.c_str(), &end, 10);  // "v", "v/vt", "v//vn", "v/vt/vn"
        if (end == tok.c_str() || (*end != '\0' && *end != '/'))
          throw invalidInput(at() + "face corner '" + tok + "' is not a vertex index");
        if (v == 0) throw invalidInput(at() + "face refers to vertex 0 (OBJ counts from 1)");
        if (v < 0 && -v > vertices)
          throw invalidInput(at() + "face refers to vertex " + tok.substr(0, size_t(end - tok.c_str())) + ", but only " +
                             std::to_string(vertices) + " vertices precede it");
        if (v > maxIndex) maxIndex = v, maxIndexLine = lineNo;
      }
      if (corners < 3) throw invalidInput(at() + "face has " + std::to_string(corners) + " corners (at least 3 needed)");
      for (int t = 0; t + 2 < corners; ++t) m.triangleMaterial.push_back(current);
    }
  }
  if (maxIndex > vertices)
    throw invalidInput(path + ": line " + std::to_string(maxIndexLine) + ": face refers to vertex " +
                       std::to_string(maxIndex) + ", but the file has " + std::to_string(vertices) + " vertices");
  return m;
}

// An STL's structure, before OpenMesh reads it (OpenMesh reads a truncated file as far as it goes
// and silently drops facets with NaN corners). A file of exactly 84 + 50 n bytes, n the count at
// byte 80, is binary (even when its header starts with "solid", as some exporters write); any
// other file must be ASCII (keywords in any case, as OpenMesh reads them): `solid` first, a last
// `endsolid` with no facet after it, finite `vertex` coordinates, and no NUL byte (a binary file
// of the wrong size is reported as such).
bool equalsNoCase(const std::string& a, const char* b) {
  const size_t n = std::strlen(b);
  if (a.size() != n) return false;
  for (size_t i = 0; i < n; ++i)
    if (std::tolower(static_cast<unsigned char>(a[i])) != b[i]) return false;
  return true;
}

void checkStl(const std::vector<unsigned char>& b, const std::string& path) {
  uint32_t n = 0;
  if (b.size() >= 84) std::memcpy(&n, b.data() + 80, 4);
  if (b.size() >= 84 && b.size() == 84 + 50 * uint64_t(n)) {
    for (uint32_t i = 0; i < n; ++i)
      for (int k = 0; k < 9; ++k) {
        float v;
        std::memcpy(&v, b.data() + 84 + 50 * size_t(i) + 12 + 4 * size_t(k), 4);
        if (!std::isfinite(v)) throw nonFiniteTriangle(path, i);
      }
    return;
  }
  const std::string text(b.begin(), b.end());
  std::istringstream in(text);
  std::string tok;
  const bool ascii = (in >> tok) && equalsNoCase(tok, "solid") && text.find('\0') == std::string::npos;
  if (!ascii) {
    if (b.size() >= 84)
      throw invalidInput(path + ": truncated or corrupt binary STL (its header declares " + std::to_string(n) +
                         " triangles, " + std::to_string(84 + 50 * uint64_t(n)) + " bytes; the file has " +
                         std::to_string(b.size()) + ")");
    throw invalidInput(path + ": not an STL file (no 'solid' keyword, and shorter than a binary STL header)");
  }
  long facet = -1;
  bool ended = false;  // an `endsolid` with no facet after it
  while (in >> tok) {
    if (equalsNoCase(tok, "facet")) ++facet, ended = false;
    if (equalsNoCase(tok, "endsolid")) ended = true;
    if (!equalsNoCase(tok, "vertex")) continue;
    for (int k = 0; k < 3 && in >> tok; ++k) {
      char* end = nullptr;
      const double v = std::strtod(tok.c_str(), &end);
      if (end != tok.c_str() && !std::isfinite(v)) throw nonFiniteTriangle(path, size_t(std::max(facet, 0L)));
    }
  }
  if (!ended) throw invalidInput(path + ": truncated ASCII STL (no 'endsolid' after its last facet)");
}

// Reads the file with OpenMesh (its logs off), asking for vertex and face colours; refuses what it cannot parse.
OmMesh readWithOpenMesh(const std::string& path, OpenMesh::IO::Options& opt) {
  omerr().disable();
  omlog().disable();
  omout().disable();
  OmMesh om;
  om.request_vertex_colors();
  om.request_face_colors();
  opt = OpenMesh::IO::Options::VertexColor | OpenMesh::IO::Options::FaceColor;
  bool read = false;
  try {
    read = OpenMesh::IO::read_mesh(om, path, opt);
  } catch (const std::bad_alloc&) {
    throw invalidInput(path + ": OpenMesh ran out of memory reading the file (corrupt?)");
  }
  if (!read) throw invalidInput(path + ": OpenMesh could not parse the file (malformed or truncated)");
  return om;
}

// The mesh's materials: the OBJ's, by order, when its material runs match the faces OpenMesh read
// (returns true), else one "default".
bool addMaterials(const std::string& path, const std::string& ext, const ObjMaterials& objMat, const OmMesh& om,
                  Mesh& out) {
  bool byOrder = false;
  if (ext == "obj") {
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
  return byOrder;
}

// OpenMesh's triangles into out, with their colours and materials.
void addTriangles(const std::string& ext, const OmMesh& om, const OpenMesh::IO::Options& opt,
                  const ObjMaterials& objMat, bool byOrder, Mesh& out) {
  // STL carries no colour (Canopy ignores the non-standard colour uses of its attribute bytes),
  // but OpenMesh's STL reader reports the colours it was asked for: they are uninitialised.
  const bool faceColor = ext != "stl" && opt.face_has_color();
  const bool vertexColor = ext != "stl" && opt.vertex_has_color();
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
}

}  // namespace

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
  // Never OpenMesh's PLY reader (it hangs on truncation) nor its OFF reader (off_loader.cpp).
  if (ext == "ply") return loadPly(path);
  if (ext == "off") return loadOff(path);
  requireReadableFile(path);
  {
    std::ifstream probe(path, std::ios::binary | std::ios::ate);
    if (probe.tellg() == 0) throw invalidInput(path + ": empty file");
  }
  ObjMaterials objMat;
  if (ext == "stl") {
    checkStl(readFile(path), path);
  } else if (ext == "obj") {
    objMat = scanObjMaterials(path);
  }
  OpenMesh::IO::Options opt;
  const OmMesh om = readWithOpenMesh(path, opt);

  Mesh out;
  const bool byOrder = addMaterials(path, ext, objMat, om, out);
  addTriangles(ext, om, opt, objMat, byOrder, out);
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
