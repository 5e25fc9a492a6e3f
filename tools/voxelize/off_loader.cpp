// off_loader.cpp: Canopy's own reader of ASCII OFF ([ST][C][N]OFF, Geomview's layout).
//
// OpenMesh's OFF reader reserved what the header declares (an absurd count ran out of memory with
// no file named), read a truncated file as far as it went, silently dropped vertices with NaN
// coordinates and faces with bad indices, read no vertex past a '#' comment line, and took the
// colour layout of a file it read from a stream from the previously opened file; for COFF it gave
// every face an uninitialised colour. So OFF does not go through OpenMesh.
//
// Layout: the keyword ([ST][C][N]OFF; binary, 4-D and n-D OFF are refused as unsupported), then
// "vertices faces [edges]" (on the keyword's line or the next), one vertex per line (x y z, then
// nx ny nz with N, then r g b [a] with C, then s t with ST), one face per line (n i_1 .. i_n, then
// an optional colour: r g b [a], or one colour-map index, which is ignored). '#' starts a comment;
// blank lines are skipped. Colours are integers 0..255 or, where any colour value in the file has a
// '.' or an exponent, floats 0..1, as 8-bit sRGB. The body must hold every declared element (the counts are checked against the size
// first), every coordinate must be finite, every index must name a vertex, and nothing but
// comments may follow the last face. Every failure is canopy::invalidInput naming the file.
//
// The result is built as ply_loader.cpp's is (polygons.h): one "default" material without colour,
// polygons fanned from their first corner, faces of fewer than 3 corners skipped, face colours (else
// the mean of the vertex colours) as linear RGB.
#include <algorithm>
#include <charconv>
#include <cmath>
#include <string_view>

#include "canopy/atomic_file.h"
#include "canopy/errors.h"
#include "mesh_io.h"
#include "polygons.h"

namespace canopy::mesh {
namespace {

// Non-empty lines of the file, comments removed, split into tokens.
class Lines {
 public:
  Lines(const uint8_t* data, size_t size) : p_(reinterpret_cast<const char*>(data)), end_(p_ + size) {}
  bool next(std::vector<std::string_view>& tok) {
    while (p_ < end_) {
      const char* eol = std::find(p_, end_, '\n');
      const char* stop = std::find(p_, eol, '#');
      ++line_;
      tok.clear();
      for (const char* q = p_; q < stop;) {
        while (q < stop && isSpace(*q)) ++q;
        const char* b = q;
        while (q < stop && !isSpace(*q)) ++q;
        if (q > b) tok.emplace_back(b, size_t(q - b));
      }
      p_ = eol < end_ ? eol + 1 : end_;
      if (!tok.empty()) return true;
    }
    return false;
  }
  size_t line() const { return line_; }

 private:
  static bool isSpace(char c) { return c == ' ' || c == '\t' || c == '\r' || c == '\f' || c == '\v'; }
  const char* p_;
  const char* end_;
  size_t line_ = 0;
};

bool toInt(std::string_view s, long long& v) {
  const auto r = std::from_chars(s.data(), s.data() + s.size(), v);
  return r.ec == std::errc() && r.ptr == s.data() + s.size();
}

bool toDouble(std::string_view s, double& v) {
  // from_chars refuses a leading '+', which printf-style writers never emit but hand edits may.
  if (!s.empty() && s[0] == '+') s.remove_prefix(1);
  const auto r = std::from_chars(s.data(), s.data() + s.size(), v);
  return r.ec == std::errc() && r.ptr == s.data() + s.size();
}

// The reader's state: the lines, the current line's tokens, and whether the colours are floats.
struct OffReader {
  Lines lines;
  std::vector<std::string_view> t;
  const std::string& name;
  // Colours are kept as read until the end: integers 0..255, or floats 0..1 where any colour value
  // in the file has a '.' or an exponent (decided once per file: "1 0 0" beside "0.5 0.5 0.5" is red).
  bool floatColors = false;

  Error fail(const std::string& what) const {
    return invalidInput(name + ": line " + std::to_string(lines.line()) + ": " + what);
  }
  // Reads r g b from token `from` on.
  void readColor(size_t from, std::array<float, 3>& rgb) {
    for (size_t k = 0; k < 3; ++k) {
      double v = 0;
      if (!toDouble(t[from + k], v) || !std::isfinite(v)) throw fail("colour value '" + std::string(t[from + k]) + "' is not a number");
      floatColors |= t[from + k].find_first_of(".eE") != std::string_view::npos;
      rgb[k] = float(std::clamp(v, 0.0, 255.0));
    }
  }
};

// What the first line (or two) declares: the vertex layout and the element counts.
struct OffHeader {
  bool color, normal;
  long long nv, nf;
};

// The keyword [ST][C][N]OFF and the counts, checked against the file's size before anything is allocated.
OffHeader readOffHeader(OffReader& r, size_t size) {
  const std::string& name = r.name;
  if (!r.lines.next(r.t)) throw invalidInput(name + ": empty OFF file");
  // The keyword: [ST][C][N][4][n]OFF.
  std::string_view key = r.t[0];
  const bool st = key.substr(0, 2) == "ST";
  if (st) key.remove_prefix(2);
  const bool color = !key.empty() && key[0] == 'C';
  if (color) key.remove_prefix(1);
  const bool normal = !key.empty() && key[0] == 'N';
  if (normal) key.remove_prefix(1);
  if (key == "4OFF" || key == "nOFF" || key == "4nOFF")
    throw unsupported(name + ": 4-D and n-D OFF files are not supported");
  if (key != "OFF") throw invalidInput(name + ": not an OFF file (its first word is not OFF, COFF, NOFF, STOFF ...)");
  std::vector<std::string_view> counts(r.t.begin() + 1, r.t.end());
  if (!counts.empty() && counts[0] == "BINARY") throw unsupported(name + ": binary OFF files are not supported");
  if (counts.empty() && !r.lines.next(counts)) throw invalidInput(name + ": truncated OFF file (no vertex and face counts)");
  long long nv = -1, nf = -1, ne = 0;
  if (counts.size() < 2 || counts.size() > 3 || !toInt(counts[0], nv) || !toInt(counts[1], nf) ||
      (counts.size() == 3 && !toInt(counts[2], ne)) || nv < 0 || nf < 0)
    throw r.fail("bad OFF counts (expected: vertices faces [edges], non-negative integers)");
  // Before anything is allocated: a vertex line holds at least "x y z\n" (6 bytes), a face line
  // "n\n" (2 bytes; a face of 3 corners at least "3 a b c\n", 8).
  if (double(nv) * 6 + double(nf) * 2 > double(size))
    throw invalidInput(name + ": the OFF header declares " + std::to_string(nv) + " vertices and " + std::to_string(nf) +
                       " faces, more than its " + std::to_string(size) + " bytes can hold (truncated or corrupt)");
  return OffHeader{color, normal, nv, nf};
}

// One vertex per line: x y z, then the normal and the colour if the keyword has them.
void readOffVertices(OffReader& r, const OffHeader& h, Polygons& poly, std::vector<std::array<float, 3>>& vertexColors) {
  const std::string& name = r.name;
  const std::vector<std::string_view>& t = r.t;
  const size_t colorAt = h.normal ? 6 : 3;  // where a vertex's colour starts
  poly.points.reserve(size_t(h.nv));
  if (h.color) vertexColors.reserve(size_t(h.nv));
  for (long long v = 0; v < h.nv; ++v) {
    if (!r.lines.next(r.t))
      throw invalidInput(name + ": truncated OFF file (" + std::to_string(v) + " of " + std::to_string(h.nv) +
                         " vertices; one vertex per line)");
    const size_t need = colorAt + (h.color ? 3 : 0);
    if (t.size() < need)
      throw r.fail("vertex " + std::to_string(v) + " (counting from 0) has " + std::to_string(t.size()) + " values, " +
                   std::to_string(need) + " expected");
    Vec3 p;
    for (size_t k = 0; k < 3; ++k) {
      if (!toDouble(t[k], p[k])) throw r.fail("vertex " + std::to_string(v) + " (counting from 0) has a coordinate '" + std::string(t[k]) + "' that is not a number");
      if (!std::isfinite(p[k])) throw r.fail("vertex " + std::to_string(v) + " (counting from 0) has a NaN or infinite coordinate");
    }
    poly.points.push_back(p);
    if (h.color) r.readColor(colorAt, vertexColors.emplace_back());
  }
}

// Faces of 3 corners or more (a line of at least 8 bytes each); fewer give no triangle. Nothing but
// comments may follow the last.
void readOffFaces(OffReader& r, const OffHeader& h, Polygons& poly, std::vector<std::array<float, 3>>& faceColors) {
  const std::string& name = r.name;
  const std::vector<std::string_view>& t = r.t;
  const long long nv = h.nv, nf = h.nf;
  poly.faceStart.push_back(0);
  for (long long f = 0; f < nf; ++f) {
    if (!r.lines.next(r.t))
      throw invalidInput(name + ": truncated OFF file (" + std::to_string(f) + " of " + std::to_string(nf) +
                         " faces; one face per line)");
    const std::string face = "face " + std::to_string(f) + " (counting from 0) ";
    long long n = -1;
    if (!toInt(t[0], n) || n < 0 || uint64_t(n) + 1 > t.size())
      throw r.fail(face + "is not a corner count followed by that many vertex indices");
    for (size_t k = 1; k <= size_t(n); ++k) {
      long long i = -1;
      if (!toInt(t[k], i) || i < 0 || i >= nv)
        throw r.fail(face + "refers to vertex '" + std::string(t[k]) + "', but the file has " + std::to_string(nv) + " vertices");
      if (n >= 3) poly.corners.push_back(uint32_t(i));
    }
    // after the indices: nothing, a colour-map index (ignored), or r g b [a]
    std::array<float, 3> rgb{};
    const bool hasColor = t.size() - 1 - size_t(n) >= 3;
    if (hasColor) r.readColor(1 + size_t(n), rgb);
    if (n < 3) continue;
    poly.faceStart.push_back(uint32_t(poly.corners.size()));
    faceColors.push_back(rgb);
    poly.faceHasRgb.push_back(hasColor);
  }
  if (r.lines.next(r.t)) throw r.fail("data after the last of the " + std::to_string(nf) + " faces the header declares");
}

}  // namespace

Mesh loadOffFromMemory(const uint8_t* data, size_t size, const std::string& name) {
  OffReader r{Lines(data, size), {}, name};
  const OffHeader h = readOffHeader(r, size);
  Polygons poly;
  std::vector<std::array<float, 3>> vertexColors, faceColors;  // as read (the scale is known at the end)
  readOffVertices(r, h, poly, vertexColors);
  readOffFaces(r, h, poly, faceColors);

  const bool floatColors = r.floatColors;
  auto toSrgb8 = [&](const std::array<float, 3>& c) {
    std::array<uint8_t, 3> b;
    for (size_t ch = 0; ch < 3; ++ch)
      b[ch] = uint8_t(std::lround(std::clamp(floatColors ? c[ch] * 255.0f : c[ch], 0.0f, 255.0f)));
    return b;
  };
  for (const auto& c : vertexColors) poly.vertexRgb.push_back(toSrgb8(c));
  if (std::find(poly.faceHasRgb.begin(), poly.faceHasRgb.end(), uint8_t(1)) != poly.faceHasRgb.end())
    for (const auto& c : faceColors) poly.faceRgb.push_back(toSrgb8(c));
  return fanPolygons(poly);  // an uncoloured face among coloured ones is white
}

Mesh loadOff(const std::string& path) {
  const std::vector<unsigned char> bytes = readFile(path);
  return loadOffFromMemory(bytes.data(), bytes.size(), path);
}

}  // namespace canopy::mesh
