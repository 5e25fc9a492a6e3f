// ply_loader.cpp: Canopy's own PLY reader (ASCII, binary little and big endian, format 1.0).
//
// OpenMesh's PLY reader loops forever on a truncated header (printing "Unsupported entry type"
// without end) and on many truncated binary bodies, so PLY does not go through OpenMesh. This
// reader trusts nothing: the header must start with `ply`, carry a `format` line and end with
// `end_header` within kMaxHeaderBytes; every property type must be a PLY type; there must be a
// `vertex` element with scalar x, y, z and a `face` element with an integer list `vertex_indices`
// (or `vertex_index`). Before anything is allocated, the body must be long enough for the fixed
// part of every element (binary: count x the record's fixed bytes; ASCII: count x its tokens);
// every read is bounds-checked, every face index must name a vertex, and data after the last
// element is refused. Every failure is canopy::invalidInput naming the file, on one line.
//
// The result is what the OpenMesh path gives for the other formats: one "default" material
// without colour, polygons fanned from their first corner, faces of fewer than 3 corners skipped,
// face colours (else the mean of the vertex colours) as linear RGB from 8-bit sRGB.
#include <algorithm>
#include <cctype>
#include <cerrno>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <sstream>

#include "canopy/atomic_file.h"
#include "canopy/errors.h"
#include "mesh_io.h"
#include "polygons.h"

namespace canopy::mesh {
namespace {

constexpr size_t kMaxHeaderBytes = 1 << 16;
constexpr uint64_t kMaxElementCount = uint64_t(1) << 32;

enum class Type { I8, U8, I16, U16, I32, U32, F32, F64 };
enum class Format { Ascii, BinaryLE, BinaryBE };

bool parseType(const std::string& s, Type& t) {
  static const std::pair<const char*, Type> names[] = {
      {"char", Type::I8},    {"int8", Type::I8},     {"uchar", Type::U8},  {"uint8", Type::U8},
      {"short", Type::I16},  {"int16", Type::I16},   {"ushort", Type::U16}, {"uint16", Type::U16},
      {"int", Type::I32},    {"int32", Type::I32},   {"uint", Type::U32},  {"uint32", Type::U32},
      {"float", Type::F32},  {"float32", Type::F32}, {"double", Type::F64}, {"float64", Type::F64}};
  for (const auto& [n, ty] : names)
    if (s == n) { t = ty; return true; }
  return false;
}

size_t sizeOf(Type t) {
  switch (t) {
    case Type::I8: case Type::U8: return 1;
    case Type::I16: case Type::U16: return 2;
    case Type::I32: case Type::U32: case Type::F32: return 4;
    case Type::F64: return 8;
  }
  return 0;
}

bool isInteger(Type t) { return t != Type::F32 && t != Type::F64; }

struct Property {
  std::string name;
  bool list = false;
  Type countType = Type::U8;  // lists only
  Type type = Type::F32;      // the scalar, or the list's items
};

struct Element {
  std::string name;
  uint64_t count = 0;
  std::vector<Property> props;
  int find(const std::string& n) const {
    for (size_t i = 0; i < props.size(); ++i)
      if (props[i].name == n) return int(i);
    return -1;
  }
};

struct Header {
  Format format = Format::Ascii;
  std::vector<Element> elements;
  size_t bodyOffset = 0;
};

std::vector<std::string> tokens(const std::string& line) {
  std::istringstream ss(line);
  std::vector<std::string> t;
  for (std::string s; ss >> s;) t.push_back(s);
  return t;
}

bool parseCount(const std::string& s, uint64_t& v) {
  if (s.empty() || s.size() > 12 || s.find_first_not_of("0123456789") != std::string::npos) return false;
  v = std::stoull(s);
  return v <= kMaxElementCount;
}

Header parseHeader(const uint8_t* data, size_t size, const std::string& name) {
  auto fail = [&](const std::string& what) { return invalidInput(name + ": " + what); };
  if (size < 4 || std::memcmp(data, "ply", 3) != 0 || (data[3] != '\n' && data[3] != '\r'))
    throw fail(size < 4 && std::memcmp(data, "ply", std::min<size_t>(size, 3)) == 0
                   ? "truncated PLY header" : "not a PLY file (no 'ply' line)");
  Header h;
  bool haveFormat = false;
  size_t at = 0;
  for (int lineNo = 1;; ++lineNo) {
    const size_t limit = std::min(size, kMaxHeaderBytes);
    const void* nl = at < limit ? std::memchr(data + at, '\n', limit - at) : nullptr;
    if (!nl)
      throw fail(size < kMaxHeaderBytes ? "truncated PLY header (no end_header line)"
                                        : "PLY header has no end_header line in its first " +
                                              std::to_string(kMaxHeaderBytes) + " bytes");
    const size_t end = size_t(static_cast<const uint8_t*>(nl) - data);
    std::string line(reinterpret_cast<const char*>(data + at), end - at);
    at = end + 1;
    if (!line.empty() && line.back() == '\r') line.pop_back();
    const std::vector<std::string> t = tokens(line);
    const std::string where = "PLY header line " + std::to_string(lineNo);
    if (lineNo == 1 || t.empty() || t[0] == "comment" || t[0] == "obj_info") continue;
    if (t[0] == "end_header") {
      if (t.size() != 1) throw fail(where + ": unexpected text after end_header");
      break;
    }
    if (t[0] == "format") {
      if (haveFormat) throw fail(where + ": a second format line");
      if (t.size() != 3 || (t[2] != "1.0" && t[2] != "1"))
        throw fail(where + ": expected 'format ascii|binary_little_endian|binary_big_endian 1.0'");
      if (t[1] == "ascii") h.format = Format::Ascii;
      else if (t[1] == "binary_little_endian") h.format = Format::BinaryLE;
      else if (t[1] == "binary_big_endian") h.format = Format::BinaryBE;
      else throw fail(where + ": unknown PLY format '" + t[1] + "'");
      haveFormat = true;
    } else if (t[0] == "element") {
      Element e;
      if (t.size() != 3 || !parseCount(t[2], e.count))
        throw fail(where + ": expected 'element NAME COUNT' with COUNT in 0..2^32");
      e.name = t[1];
      h.elements.push_back(e);
    } else if (t[0] == "property") {
      if (h.elements.empty()) throw fail(where + ": property before any element");
      Property p;
      if (t.size() == 5 && t[1] == "list") {
        p.list = true;
        if (!parseType(t[2], p.countType) || !parseType(t[3], p.type))
          throw fail(where + ": unknown property type in '" + line + "'");
        if (!isInteger(p.countType)) throw fail(where + ": a list count must have an integer type");
        p.name = t[4];
      } else if (t.size() == 3 && t[1] != "list") {
        if (!parseType(t[1], p.type)) throw fail(where + ": unknown property type '" + t[1] + "'");
        p.name = t[2];
      } else {
        throw fail(where + ": expected 'property TYPE NAME' or 'property list COUNTTYPE TYPE NAME'");
      }
      h.elements.back().props.push_back(p);
    } else {
      throw fail(where + ": unknown keyword '" + t[0] + "'");
    }
  }
  if (!haveFormat) throw fail("PLY header has no format line");
  h.bodyOffset = at;
  return h;
}

// Reads values of the body one at a time; every read is bounds-checked.
class Body {
 public:
  Body(const uint8_t* data, size_t size, size_t offset, Format f, const std::string& name)
      : p_(data + offset), end_(data + size), format_(f), name_(name) {}

  // Where the next value belongs (for error messages).
  void at(const Element& e, uint64_t item) { element_ = &e; item_ = item; }

  double read(Type t) {
    if (format_ == Format::Ascii) return readAscii(t);
    const size_t n = sizeOf(t);
    if (size_t(end_ - p_) < n) throw truncated();
    uint8_t b[8];
    std::memcpy(b, p_, n);
    p_ += n;
    if (format_ == Format::BinaryBE) std::reverse(b, b + n);  // the host is little endian
    switch (t) {
      case Type::I8: { int8_t v; std::memcpy(&v, b, 1); return v; }
      case Type::U8: return b[0];
      case Type::I16: { int16_t v; std::memcpy(&v, b, 2); return v; }
      case Type::U16: { uint16_t v; std::memcpy(&v, b, 2); return v; }
      case Type::I32: { int32_t v; std::memcpy(&v, b, 4); return v; }
      case Type::U32: { uint32_t v; std::memcpy(&v, b, 4); return v; }
      case Type::F32: { float v; std::memcpy(&v, b, 4); return double(v); }
      case Type::F64: { double v; std::memcpy(&v, b, 8); return v; }
    }
    return 0;
  }

  // After the last element: only whitespace (ASCII) or nothing (binary) may follow.
  void requireEnd() {
    if (format_ == Format::Ascii)
      while (p_ < end_ && std::isspace(*p_)) ++p_;
    if (p_ != end_)
      throw invalidInput(name_ + ": " + std::to_string(end_ - p_) +
                         " bytes of unexpected data after the last PLY element");
  }

  Error truncated() const {
    return invalidInput(name_ + ": truncated PLY body (element '" + element_->name + "' " +
                        std::to_string(item_) + " of " + std::to_string(element_->count) + " ends early)");
  }

 private:
  double readAscii(Type t) {
    while (p_ < end_ && std::isspace(*p_)) ++p_;
    const uint8_t* s = p_;
    while (p_ < end_ && !std::isspace(*p_)) ++p_;
    if (s == p_) throw truncated();
    const std::string tok(reinterpret_cast<const char*>(s), size_t(p_ - s));
    char* e = nullptr;
    double v = 0;
    if (isInteger(t)) {
      errno = 0;
      const long long i = std::strtoll(tok.c_str(), &e, 10);
      if (errno != 0) e = nullptr;
      v = double(i);
    } else {
      v = std::strtod(tok.c_str(), &e);
    }
    if (!e || *e != '\0')
      throw invalidInput(name_ + ": bad " + (isInteger(t) ? "integer" : "number") + " '" +
                         tok.substr(0, 32) + "' in PLY element '" + element_->name + "' " +
                         std::to_string(item_));
    return v;
  }

  const uint8_t* p_;
  const uint8_t* end_;
  Format format_;
  std::string name_;
  const Element* element_ = nullptr;
  uint64_t item_ = 0;
};

uint8_t toByte(double v, Type t) {
  if (!isInteger(t)) v *= 255.0;
  if (!(v > 0)) return 0;  // also NaN
  return v >= 255 ? 255 : uint8_t(std::lround(v));
}

// The elements and properties Canopy reads: vertex positions, face corners, and colours if any.
struct PlyLayout {
  const Element* vertex = nullptr;
  const Element* face = nullptr;
  int xyz[3];
  int indices;
  int vRGB[3], fRGB[3];
  bool vertexColor, faceColor;
};

// The properties red, green and blue (or diffuse_*) of element e, all scalar; false if one is missing.
bool colourOf(const Element& e, int out[3]) {
  const char* n[3] = {"red", "green", "blue"};
  const char* d[3] = {"diffuse_red", "diffuse_green", "diffuse_blue"};
  bool all = true;
  for (int c = 0; c < 3; ++c) {
    out[c] = e.find(n[c]);
    if (out[c] < 0) out[c] = e.find(d[c]);
    all &= out[c] >= 0 && !e.props[size_t(out[c])].list;
  }
  return all;
}

// Finds the vertex and face elements and the properties Canopy needs; refuses a file without them.
PlyLayout plyLayout(const Header& h, const std::string& name) {
  auto fail = [&](const std::string& what) { return invalidInput(name + ": " + what); };
  PlyLayout y;
  for (const Element& e : h.elements) {
    if (e.count > 0 && e.props.empty()) throw fail("PLY element '" + e.name + "' has no properties");
    if (e.name == "vertex" && !y.vertex) y.vertex = &e;
    if (e.name == "face" && !y.face) y.face = &e;
  }
  if (!y.vertex) throw fail("PLY file has no vertex element");
  if (!y.face) throw fail("PLY file has no face element");
  for (int k = 0; k < 3; ++k) {
    const char* n[3] = {"x", "y", "z"};
    y.xyz[k] = y.vertex->find(n[k]);
    if (y.xyz[k] < 0 || y.vertex->props[size_t(y.xyz[k])].list)
      throw fail(std::string("PLY vertex element has no scalar property ") + n[k]);
  }
  y.indices = y.face->find("vertex_indices");
  if (y.indices < 0) y.indices = y.face->find("vertex_index");
  if (y.indices < 0 || !y.face->props[size_t(y.indices)].list)
    throw fail("PLY face element has no list property vertex_indices");
  if (!isInteger(y.face->props[size_t(y.indices)].type)) throw fail("PLY vertex_indices must have an integer type");
  y.vertexColor = colourOf(*y.vertex, y.vRGB);
  y.faceColor = colourOf(*y.face, y.fRGB);
  return y;
}

// The body must hold at least the fixed part of every element before anything is allocated.
void checkBodySize(const Header& h, size_t size, const std::string& name) {
  auto fail = [&](const std::string& what) { return invalidInput(name + ": " + what); };
  const uint64_t body = size - h.bodyOffset;
  uint64_t need = 0;
  for (const Element& e : h.elements) {
    uint64_t record = 0;
    for (const Property& p : e.props)
      record += h.format == Format::Ascii ? 2 : sizeOf(p.list ? p.countType : p.type);  // a token is >= 2 bytes
    need += e.count * record;
  }
  if (h.format == Format::Ascii && need > 0) need -= 1;  // the last token needs no separator
  if (need > body)
    throw fail("truncated PLY body (" + std::to_string(body) + " bytes; the header's elements need at least " +
               std::to_string(need) + ")");
}

// Reads every element of the body, keeping the vertices, face corners and colours.
Polygons readPlyBody(const uint8_t* data, size_t size, const Header& h, const PlyLayout& y, const std::string& name) {
  auto fail = [&](const std::string& what) { return invalidInput(name + ": " + what); };
  const Element* vertex = y.vertex;
  const Element* face = y.face;
  Polygons poly;
  std::vector<Vec3>& points = poly.points;
  std::vector<std::array<uint8_t, 3>>& vertexRgb = poly.vertexRgb;
  std::vector<uint32_t>& corners = poly.corners;
  std::vector<uint32_t>& faceStart = poly.faceStart;
  std::vector<std::array<uint8_t, 3>>& faceRgb = poly.faceRgb;
  Body in(data, size, h.bodyOffset, h.format, name);
  std::vector<double> scalar;
  for (const Element& e : h.elements) {
    const bool isVertex = &e == vertex, isFace = &e == face;
    if (isVertex) {
      points.reserve(size_t(e.count));
      if (y.vertexColor) vertexRgb.reserve(size_t(e.count));
    }
    if (isFace) faceStart.reserve(size_t(e.count));
    for (uint64_t item = 0; item < e.count; ++item) {
      in.at(e, item);
      scalar.assign(e.props.size(), 0.0);
      for (size_t pi = 0; pi < e.props.size(); ++pi) {
        const Property& p = e.props[pi];
        if (!p.list) {
          scalar[pi] = in.read(p.type);
          continue;
        }
        const double n = in.read(p.countType);
        if (n < 0) throw fail("PLY element '" + e.name + "' " + std::to_string(item) + " has a negative list length");
        const bool keep = isFace && int(pi) == y.indices;
        if (keep) faceStart.push_back(uint32_t(corners.size()));
        for (uint64_t k = 0; k < uint64_t(n); ++k) {
          const double v = in.read(p.type);
          if (!keep) continue;
          if (v < 0 || v >= double(vertex->count))
            throw fail("PLY face " + std::to_string(item) + " references vertex " + std::to_string(int64_t(v)) +
                       " (the file has " + std::to_string(vertex->count) + ")");
          corners.push_back(uint32_t(v));
        }
      }
      if (isVertex) {
        points.push_back({scalar[size_t(y.xyz[0])], scalar[size_t(y.xyz[1])], scalar[size_t(y.xyz[2])]});
        if (y.vertexColor)
          vertexRgb.push_back({toByte(scalar[size_t(y.vRGB[0])], vertex->props[size_t(y.vRGB[0])].type),
                               toByte(scalar[size_t(y.vRGB[1])], vertex->props[size_t(y.vRGB[1])].type),
                               toByte(scalar[size_t(y.vRGB[2])], vertex->props[size_t(y.vRGB[2])].type)});
      }
      if (isFace && y.faceColor)
        faceRgb.push_back({toByte(scalar[size_t(y.fRGB[0])], face->props[size_t(y.fRGB[0])].type),
                           toByte(scalar[size_t(y.fRGB[1])], face->props[size_t(y.fRGB[1])].type),
                           toByte(scalar[size_t(y.fRGB[2])], face->props[size_t(y.fRGB[2])].type)});
    }
  }
  in.requireEnd();
  faceStart.push_back(uint32_t(corners.size()));
  return poly;
}

}  // namespace

Mesh loadPlyFromMemory(const uint8_t* data, size_t size, const std::string& name) {
  if (size == 0) throw invalidInput(name + ": empty file");
  const Header h = parseHeader(data, size, name);
  const PlyLayout layout = plyLayout(h, name);
  checkBodySize(h, size, name);
  Polygons poly = readPlyBody(data, size, h, layout, name);
  return fanPolygons(poly);
}

Mesh loadPly(const std::string& path) {
  const std::vector<unsigned char> bytes = readFile(path);
  return loadPlyFromMemory(bytes.data(), bytes.size(), path);
}

}  // namespace canopy::mesh
