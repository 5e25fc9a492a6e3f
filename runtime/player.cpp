// player.cpp: see player.h.
#include "runtime/player.h"

#include <algorithm>
#include <cassert>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <exception>
#include <fstream>
#include <limits>
#include <map>
#include <memory>
#include <sstream>
#include <thread>

#include "canopy/atomic_file.h"
#include "canopy/cli.h"
#include "canopy/errors.h"
#include "canopy/json_file.h"
#include "formats/canopy_file.h"
#include "formats/scene_json.h"
#include "runtime/backend.h"
#include "runtime/image_io.h"
#include "runtime/streaming.h"

namespace canopy::play {
namespace {

constexpr double kPi = 3.14159265358979323846;

// "orbit:a=1,b=2" -> {a:1, b:2}; throws Usage naming `what` for a malformed or unknown key.
// Whether v is finite as a float too (a larger double cast to float is undefined).
bool fitsFloat(double v) { return std::fabs(v) <= double(std::numeric_limits<float>::max()); }

std::map<std::string, double> parseKeys(const std::string& spec, const std::string& what,
                                        const std::vector<std::string>& allowed) {
  std::map<std::string, double> kv;
  const size_t colon = spec.find(':');
  if (colon == std::string::npos) return kv;
  std::stringstream ss(spec.substr(colon + 1));
  std::string item;
  while (std::getline(ss, item, ',')) {
    const size_t eq = item.find('=');
    if (eq == std::string::npos) throw usageError(what + " '" + spec + "': expected key=value, got '" + item + "'");
    const std::string key = item.substr(0, eq);
    if (std::find(allowed.begin(), allowed.end(), key) == allowed.end())
      throw usageError(what + " '" + spec + "': unknown key '" + key + "'");
    char* end = nullptr;
    const std::string val = item.substr(eq + 1);
    const double v = std::strtod(val.c_str(), &end);
    if (val.empty() || *end != '\0' || !fitsFloat(v))  // the camera and sun are floats
      throw usageError(what + " '" + spec + "': bad number '" + val + "'");
    kv[key] = v;
  }
  return kv;
}

double get(const std::map<std::string, double>& kv, const char* k, double def) {
  auto it = kv.find(k);
  return it == kv.end() ? def : it->second;
}

bool startsWith(const std::string& s, const char* p) { return s.rfind(p, 0) == 0; }

V3 jsonV3(const nlohmann::json& j, const std::string& what) {
  if (!j.is_array() || j.size() != 3) throw invalidInput(what + ": expected [x, y, z]");
  V3 v{};
  for (int a = 0; a < 3; ++a) {
    if (!j[size_t(a)].is_number()) throw invalidInput(what + ": expected numbers");
    const double x = j[size_t(a)].get<double>();
    if (!fitsFloat(x)) throw invalidInput(what + ": not finite (in single precision)");
    (a == 0 ? v.x : a == 1 ? v.y : v.z) = float(x);
  }
  return v;
}

struct Key {
  double frame;
  V3 a, b;
  double fov;
};

// Keyframes {"keyframes": [{"frame": F, <fieldA>: [..], <fieldB>: [..], "fov": deg}, ...]}, sorted.
std::vector<Key> readKeyframes(const std::string& path, const char* fieldA, const char* fieldB) {
  nlohmann::json j = readJsonFile(path);
  if (!j.is_object() || !j.contains("keyframes") || !j["keyframes"].is_array() || j["keyframes"].empty())
    throw invalidInput(path + ": expected {\"keyframes\": [...]} with at least one keyframe");
  std::vector<Key> keys;
  for (size_t i = 0; i < j["keyframes"].size(); ++i) {
    const auto& k = j["keyframes"][i];
    const std::string what = path + ": keyframe " + std::to_string(i);
    if (!k.is_object() || !k.contains("frame") || !k["frame"].is_number()) throw invalidInput(what + ": needs \"frame\"");
    Key key{k["frame"].get<double>(), {}, {}, 45.0};
    if (!k.contains(fieldA)) throw invalidInput(what + ": needs \"" + fieldA + "\"");
    key.a = jsonV3(k[fieldA], what + " " + fieldA);
    if (fieldB) {
      if (!k.contains(fieldB)) throw invalidInput(what + ": needs \"" + fieldB + "\"");
      key.b = jsonV3(k[fieldB], what + " " + fieldB);
    }
    if (k.contains("fov")) {
      if (!k["fov"].is_number()) throw invalidInput(what + ": fov must be a number");
      key.fov = k["fov"].get<double>();
      if (!(key.fov > 0.1 && key.fov < 179.0)) throw invalidInput(what + ": fov must be in (0.1, 179) degrees");
    }
    keys.push_back(key);
  }
  std::stable_sort(keys.begin(), keys.end(), [](const Key& x, const Key& y) { return x.frame < y.frame; });
  return keys;
}

Key interpolate(const std::vector<Key>& keys, double f) {
  if (f <= keys.front().frame) return keys.front();
  if (f >= keys.back().frame) return keys.back();
  size_t i = 1;
  while (keys[i].frame < f) ++i;
  const Key &k0 = keys[i - 1], &k1 = keys[i];
  const float s = float((f - k0.frame) / std::max(k1.frame - k0.frame, 1e-12));
  return Key{f, k0.a + (k1.a - k0.a) * s, k0.b + (k1.b - k0.b) * s, k0.fov + (k1.fov - k0.fov) * s};
}

CameraView makeCamera(V3 position, V3 target, double fovDeg, int width, int height) {
  CameraView c{};
  c.position = position;
  c.forward = normalize(target - position);
  V3 up = v3(0, 1, 0);
  if (std::fabs(dot(up, c.forward)) > 0.999f) up = v3(0, 0, 1);
  const V3 right = normalize(cross(c.forward, up));
  const V3 trueUp = cross(right, c.forward);
  const float th = float(std::tan(fovDeg * kPi / 360.0));
  const float aspect = float(width) / float(height);
  c.right = right * (th * aspect);
  c.up = trueUp * th;
  c.pixelAngle = 2.0f * th / float(height);
  c.width = width;
  c.height = height;
  return c;
}

V3 fromAngles(double azimuthDeg, double elevationDeg) {
  const double az = azimuthDeg * kPi / 180.0, el = elevationDeg * kPi / 180.0;
  return v3(float(std::cos(el) * std::sin(az)), float(std::sin(el)), float(std::cos(el) * std::cos(az)));
}

double percentile(std::vector<double> v, double q) {
  if (v.empty()) return 0.0;
  std::sort(v.begin(), v.end());
  const double pos = q * double(v.size() - 1);
  const size_t i = size_t(pos);
  const double f = pos - double(i);
  return i + 1 < v.size() ? v[i] * (1 - f) + v[i + 1] * f : v[i];
}

// The frames a run has written; unless the run reaches the end (keep()), they are removed, so a
// failed run leaves no partial sequence behind.
class WrittenFrames {
 public:
  WrittenFrames() = default;
  WrittenFrames(const WrittenFrames&) = delete;
  WrittenFrames& operator=(const WrittenFrames&) = delete;
  ~WrittenFrames() {
    if (!kept_)
      for (const std::string& p : paths_) std::remove(p.c_str());
  }
  void add(const std::string& path) { paths_.push_back(path); }
  void keep() { kept_ = true; }

 private:
  std::vector<std::string> paths_;
  bool kept_ = false;
};

// The parts of a frame pattern: prefix, one %d / %Nd / %0Nd, suffix ("%%" already made '%').
struct FramePattern {
  std::string prefix, suffix;
  char pad = ' ';
  int width = 0;
};

constexpr int kMaxFrameWidth = 32;  // widest %Nd accepted (frames are < 10^6, so more is only padding)

// Parses `pattern` (it contains a '%'); throws Usage naming it unless it holds exactly one integer
// conversion %d, %Nd or %0Nd and otherwise only "%%".
FramePattern parseFramePattern(const std::string& pattern) {
  const std::string bad = "-o " + pattern + ": a frame pattern takes one integer conversion such as %04d (and %% for a literal %)";
  FramePattern fp;
  bool seen = false;
  for (size_t i = 0; i < pattern.size(); ++i) {
    std::string& part = seen ? fp.suffix : fp.prefix;
    if (pattern[i] != '%') {
      part += pattern[i];
      continue;
    }
    if (i + 1 < pattern.size() && pattern[i + 1] == '%') {
      part += '%';
      ++i;
      continue;
    }
    if (seen) throw usageError(bad);
    size_t j = i + 1;
    if (j < pattern.size() && pattern[j] == '0') {
      fp.pad = '0';
      ++j;
    }
    int width = 0;
    while (j < pattern.size() && pattern[j] >= '0' && pattern[j] <= '9' && width <= kMaxFrameWidth) width = width * 10 + (pattern[j++] - '0');
    if (j >= pattern.size() || pattern[j] != 'd' || width > kMaxFrameWidth) throw usageError(bad);
    fp.width = width;
    seen = true;
    i = j;
  }
  if (!seen) throw usageError(bad);
  return fp;
}

}  // namespace

std::string frameFileName(const std::string& pattern, int frame, int frames) {
  if (pattern.find('%') == std::string::npos) {
    if (frames > 1) throw usageError("-o " + pattern + ": " + std::to_string(frames) + " frames need a pattern such as frames/f_%04d.exr");
    return pattern;
  }
  const FramePattern fp = parseFramePattern(pattern);
  assert(frame >= 0);
  std::string number = std::to_string(frame);
  if (number.size() < size_t(fp.width)) number.insert(0, size_t(fp.width) - number.size(), fp.pad);
  return fp.prefix + number + fp.suffix;
}

std::vector<FrameSetup> framePlan(const PlayOptions& o, const HostScene& scene) {
  if (o.width < 1 || o.height < 1 || o.width > 8192 || o.height > 8192)
    throw usageError("--size " + std::to_string(o.width) + "x" + std::to_string(o.height) + ": each side must be 1..8192");
  if (o.frames < 1 || o.frames > 1000000) throw usageError("--frames must be 1..1000000");
  V3 centre = v3(0, 0, 0);
  float radius = 1.0f;
  if (!scene.empty) {
    const V3 lo = v3(scene.boundsLo[0], scene.boundsLo[1], scene.boundsLo[2]);
    const V3 hi = v3(scene.boundsHi[0], scene.boundsHi[1], scene.boundsHi[2]);
    centre = (lo + hi) * 0.5f;
    radius = std::max(0.5f * length(hi - lo), 1e-3f);
  }
  // Further than this from the scene, single-precision ray positions lose the scene (squares of
  // coordinates near 1e19 overflow; a NaN position crashed the descent); the scene is well under
  // a pixel wide long before (1e-4 rad).
  const float maxDistance = 1.0e4f * radius;
  auto fromCentre = [&](V3 p) {  // in double: float squares overflow at 1.8e19
    return std::hypot(double(p.x) - centre.x, double(p.y) - centre.y, double(p.z) - centre.z);
  };
  std::vector<FrameSetup> plan(size_t(o.frames));
  const double n = double(o.frames);
  // camera
  if (o.camera == "orbit" || startsWith(o.camera, "orbit:")) {
    const auto kv = parseKeys(o.camera, "--camera", {"azimuth", "elevation", "distance", "fov", "turns", "height"});
    const double fov = get(kv, "fov", 40.0);
    if (!(fov > 0.1 && fov < 179.0)) throw usageError("--camera: fov must be in (0.1, 179) degrees");
    // default distance: the bounding sphere fills the vertical field of view (with 10% margin)
    const double dist = get(kv, "distance", 1.1 * radius / std::sin(fov * kPi / 360.0));
    if (!(dist > 0)) throw usageError("--camera: distance must be > 0");
    for (int f = 0; f < o.frames; ++f) {
      const double az = get(kv, "azimuth", 30.0) + 360.0 * get(kv, "turns", 1.0) * double(f) / n;
      const V3 target = centre + v3(0, float(get(kv, "height", 0.0)), 0);
      const V3 pos = target + fromAngles(az, get(kv, "elevation", 20.0)) * float(dist);
      if (!(fromCentre(pos) <= maxDistance))
        throw usageError("--camera: the orbit puts the camera " + formatNumber(fromCentre(pos)) + " m from the scene's centre, more than 10^4 scene radii (" +
                         formatNumber(maxDistance) + " m): too far for single-precision ray marching");
      plan[size_t(f)].camera = makeCamera(pos, target, fov, o.width, o.height);
    }
  } else {
    const auto keys = readKeyframes(o.camera, "position", "target");
    for (int f = 0; f < o.frames; ++f) {
      const Key k = interpolate(keys, double(f));
      if (!(fromCentre(k.a) <= maxDistance))
        throw invalidInput(o.camera + ": the camera at frame " + std::to_string(f) + " is more than 10^4 scene radii (" +
                           formatNumber(maxDistance) + " m) from the scene's centre: too far for single-precision ray marching");
      const float span = length(k.b - k.a);
      if (!(span > 0.0f)) throw invalidInput(o.camera + ": position and target coincide at frame " + std::to_string(f));
      if (!std::isfinite(span)) throw invalidInput(o.camera + ": position and target too far apart at frame " + std::to_string(f));
      plan[size_t(f)].camera = makeCamera(k.a, k.b, k.fov, o.width, o.height);
    }
  }
  // sun
  if (o.sun == "orbit" || startsWith(o.sun, "orbit:")) {
    const auto kv = parseKeys(o.sun, "--sun", {"azimuth", "elevation", "turns"});
    for (int f = 0; f < o.frames; ++f)
      plan[size_t(f)].toSun = fromAngles(get(kv, "azimuth", 40.0) + 360.0 * get(kv, "turns", 0.0) * double(f) / n, get(kv, "elevation", 50.0));
  } else if (o.sun.size() > 5 && o.sun.substr(o.sun.size() - 5) == ".json") {
    const auto keys = readKeyframes(o.sun, "direction", nullptr);
    for (int f = 0; f < o.frames; ++f) {
      const V3 d = interpolate(keys, double(f)).a;
      const float len = length(d);
      if (!(len > 0.0f && std::isfinite(len)))
        throw invalidInput(o.sun + ": zero or overflowing sun direction at frame " + std::to_string(f));
      plan[size_t(f)].toSun = normalize(d);
    }
  } else {
    double x = 0, y = 0, z = 0;
    char tail;
    // normalised in double precision: any finite, non-zero direction (1e20,1e20,0 included)
    const bool parsed = std::sscanf(o.sun.c_str(), "%lf,%lf,%lf%c", &x, &y, &z, &tail) == 3;
    const double h = std::hypot(x, y, z);  // inf or NaN where a component is
    if (!parsed || !(h > 0.0) || !std::isfinite(h))
      throw usageError("--sun '" + o.sun + "': expected x,y,z (towards the sun), orbit[:azimuth=..,elevation=..,turns=..] or a .json path");
    for (auto& p : plan) p.toSun = v3(float(x / h), float(y / h), float(z / h));
  }
  return plan;
}

// Whether spec is one number and nothing after it (the numeric spelling of --far-field, --adaptive
// and --ground); the number in v (NaN for "nan", which the callers' ranges refuse).
static bool parseNumber(const std::string& spec, double& v) {
  char tail;
  return std::sscanf(spec.c_str(), "%lf%c", &v, &tail) == 1;
}

// --far-field: -1 off, 0 auto, > 0 the distance (ShadeParams::farStart).
static float parseFarField(const std::string& spec) {
  if (spec == "off") return -1.0f;
  if (spec == "auto") return 0.0f;
  double v = 0;
  if (!parseNumber(spec, v) || !(v > 0.0 && v <= double(kMaxWorldCoordinate)))
    throw usageError("--far-field '" + spec + "': expected auto, off or a distance D (scene units, 0 < D <= 1e9)");
  return float(v);
}

float adaptiveTolerance(const PlayOptions& o) {
  if (o.adaptive == "auto")
    return o.stereoIpd == 0.0f && !o.converge && uint64_t(o.width) * uint64_t(o.height) >= kAdaptiveAutoPixels ? kAdaptiveAutoTolerance : 0.0f;
  if (o.adaptive == "off") return 0.0f;
  double v = 0;
  if (!parseNumber(o.adaptive, v) || !(v >= 0.0 && v <= 1.0e3))
    throw usageError("--adaptive '" + o.adaptive + "': expected auto, off or a tolerance in [0, 1000] (0: off)");
  if (v > 0.0 && o.stereoIpd > 0.0f) throw usageError("--adaptive is for one eye: not with --stereo");
  return float(v);
}

ShadeParams shadeParams(const PlayOptions& o) {
  ShadeParams shade{};
  shade.sun[0] = shade.sun[1] = shade.sun[2] = o.sunIntensity;
  for (int c = 0; c < 3; ++c) shade.direct[c] = o.directSun ? shade.sun[c] : 0.0f;
  shade.ambient = o.ambient;
  shade.sigma = o.sigma;
  shade.stepFactor = o.stepFactor;
  shade.lodBias = o.lodBias;
  shade.stopT = o.stopTransmittance;
  shade.stepGrowthT = o.stepGrowthT;
  shade.stepGrowthMax = o.stepGrowthMax;
  shade.shadowAperture = o.shadowAperture;
  // Without the direct term no shadow is needed (--no-direct-sun: the indirect light alone).
  shade.shadows = !o.shadows || !o.directSun ? kShadowsOff : (o.shadowMethod == "cone" ? kShadowsCone : kShadowsMap);
  shade.shadowMapCells = o.shadowMapCells;
  shade.shadowMapBias = o.shadowMapBias;
  shade.descentCache = o.descentCache ? 1 : 0;
  shade.descentTable = o.descentTable ? 1 : 0;
  shade.holdEmpty = o.holdEmpty ? 1 : 0;
  shade.skipEmptyBlocks = o.skipEmptyBlocks ? 1 : 0;
  shade.exactLight = o.exactLight ? 1 : 0;
  shade.shadowMapMaxVoxels = o.shadowMapMaxVoxels;
  shade.stereoLayer = o.stereoIpd > 0.0f ? 2.0f * o.stereo.maxSpread : 0.0f;  // a front layer is coherent (stereo.h)
  shade.farStart = parseFarField(o.farField);
  return shade;
}

// --ground: 0 none, 1 auto, 2 the height in y.
static int parseGround(const std::string& spec, float& y) {
  if (spec == "none") return 0;
  if (spec == "auto") return 1;
  double v = 0;
  if (!parseNumber(spec, v) || !(std::fabs(v) <= double(kMaxWorldCoordinate)))
    throw usageError("--ground '" + spec + "': expected none, auto or a height (world units, |Y| <= 1e9)");
  y = float(v);
  return 2;
}

void setGround(const PlayOptions& o, const HostScene& scene, ShadeParams& shade) {
  float y = 0.0f;
  const int mode = parseGround(o.ground, y);
  if (mode == 1) y = scene.groundBase;
  shade.ground = mode != 0 && std::isfinite(y) ? 1 : 0;
  shade.groundY = shade.ground ? y : 0.0f;
  for (int c = 0; c < 3; ++c) shade.groundAlbedo[c] = o.groundAlbedo[c];
}

namespace {

void validateOptions(const PlayOptions& o) {
  if (!o.output.empty()) {
    if (!isImageName(o.output)) throw usageError("-o " + o.output + ": output must end in .png or .exr");
    frameFileName(o.output, 0, o.frames);  // validates the pattern before any work
  }
  if (!o.rightOutput.empty()) {
    if (!(o.stereoIpd > 0.0f)) throw usageError("--right-output needs --stereo IPD");
    if (o.output.empty()) throw usageError("--right-output needs -o for the left eye");
    if (!isImageName(o.rightOutput)) throw usageError("--right-output " + o.rightOutput + ": output must end in .png or .exr");
    frameFileName(o.rightOutput, 0, o.frames);
  }
  if (!(o.cacheMb > 0.0) || o.cacheMb > 1.0e6) throw usageError("--cache-mb must be in (0, 1e6]");
  for (float v : {o.sigma, o.stepFactor, o.ambient, o.sunIntensity, o.shadowAperture, o.lodBias})
    if (!std::isfinite(v)) throw usageError("shading parameters must be finite");
  if (!(o.sigma >= 0.0f) || !(o.stepFactor > 0.01f) || !(o.ambient >= 0.0f) || !(o.sunIntensity >= 0.0f) || !(o.shadowAperture >= 0.0f))
    throw usageError("--sigma, --ambient, --sun-intensity and --shadow-aperture must be >= 0 and --step > 0.01");
  if (o.warpTileWidth < 1 || o.warpTileWidth > 32 || 32 % o.warpTileWidth != 0) throw usageError("--warp-tile must be 1, 2, 4, 8, 16 or 32");
  if (o.stereoHoleOrder != "tile" && o.stereoHoleOrder != "kind")
    throw usageError("--stereo-holes must be tile or kind, got '" + o.stereoHoleOrder + "'");
  if (o.stereoHoleBlocks != 0 && o.stereoHoleBlocks != 6) throw usageError("--stereo-hole-blocks must be 0 or 6");
  if (o.shadowMethod != "map" && o.shadowMethod != "cone") throw usageError("--shadows must be map or cone, got '" + o.shadowMethod + "'");
  if (!(o.stopTransmittance >= 0.0f && o.stopTransmittance <= 0.5f)) throw usageError("--stop-opacity must be in [0.5, 1]");
  if (!(o.stepGrowthT >= 0.0f && o.stepGrowthT <= 1.0f)) throw usageError("--step-growth must be in [0, 1]");
  if (!(o.stepGrowthMax >= 1.0f && o.stepGrowthMax <= 64.0f)) throw usageError("--step-growth-max must be in [1, 64]");
  if (!(o.shadowMapBias >= 0.0f && o.shadowMapBias <= 64.0f)) throw usageError("--shadow-map-bias must be in [0, 64]");
  if (!(o.shadowMapCells >= 0.25f && o.shadowMapCells <= 1024.0f) || o.shadowMapMaxVoxels < 27 || o.shadowMapMaxVoxels > (1u << 28))
    throw usageError("--shadow-map-cells must be in [0.25, 1024] and --shadow-map-voxels in [27, 2^28]");
  if (!(o.stereoIpd >= 0.0f && o.stereoIpd <= 1.0e3f)) throw usageError("--stereo must be an eye separation in (0, 1000] scene units");
  if (o.stereoFill != "reproject" && o.stereoFill != "trace") throw usageError("--stereo-fill must be reproject or trace, got '" + o.stereoFill + "'");
  if (!(o.stereo.maxSpread >= 0.0f && o.stereo.maxSpread <= 1.0e3f)) throw usageError("--stereo-spread must be in [0, 1000] pixels");
  if (!(o.stereo.solidAlpha >= 0.0f && o.stereo.solidAlpha <= 1.0f)) throw usageError("--stereo-solid must be in [0, 1]");
  if (o.tiles < 0 || o.tiles > 64) throw usageError("--tiles must be 0..64");
  adaptiveTolerance(o);
  if (o.loaderThreads < 0 || o.loaderThreads > 64) throw usageError("--loader-threads must be 0..64 (0: the host's threads)");
  float groundY;
  parseGround(o.ground, groundY);
  parseFarField(o.farField);
  for (float a : o.groundAlbedo)
    if (!(a >= 0.0f && a <= 1.0f)) throw usageError("--ground-albedo must be R,G,B (or one value) in [0, 1]");
}

// The renderers a run uses: the CPU, one GPU, or every GPU for a plain "cuda".
std::vector<int> deviceList(const Device& device) {
  if (!device.isCuda()) return {-1};
  if (device.index >= 0) return {device.index};
  std::vector<int> all;
  for (int i = 0; i < std::max(cudaDeviceCount(), 1); ++i) all.push_back(i);
  return all;
}

// One band of the frame and the renderer, cache and loader that draw it.
struct Tile {
  int device = -1;  // CUDA ordinal, -1 for the CPU
  std::unique_ptr<Backend> backend;
  std::unique_ptr<Streamer> streamer;
  Band band;
  uint32_t stamp = 0;
  uint64_t passes = 0;
  uint32_t missing = 0;           // this frame's last pass
  double firstEyeS = 0.0;         // this frame's render time: the traced eye
  double secondEyeS = 0.0;        // stereo's second eye (reprojection and holes, or traced in full)
  double reprojectS = 0.0;        // of it, the reprojection (before the holes' trace)
  uint64_t traced = 0;            // second-eye pixels traced this frame (last pass)
  uint64_t tracedBehind = 0;      // of them, traced only behind a reprojected front
  uint64_t filled = 0;            // --adaptive: the traced eye's pixels filled, not traced, this frame (last pass)
  std::vector<double> costMs;     // per frame, for the report
};

// The cameras of one frame: the traced one (the centre, or stereo's left eye) and stereo's right.
struct EyeCameras {
  CameraView traced, right;
  float disparityScale = 0.0f;  // > 0: stereo
};

EyeCameras eyeCameras(const PlayOptions& o, const CameraView& centre) {
  EyeCameras e;
  e.traced = e.right = centre;
  if (o.stereoIpd > 0.0f) {
    stereoEyes(centre, o.stereoIpd, e.traced, e.right);
    e.disparityScale = stereoDisparityScale(centre, o.stereoIpd);
  }
  return e;
}

// The passes of one frame on one tile (all of them when `complete`, until no loadable page is
// missing; else one: real time). The stamps, cache and loader are the tile's own.
void renderTileFrame(Tile& t, const PlayOptions& o, const HostScene& scene, const ShadeParams& shade, const EyeCameras& eyes, bool complete) {
  const bool stereo = eyes.disparityScale > 0.0f;
  const uint32_t frameStart = t.stamp + 1;
  t.firstEyeS = t.secondEyeS = t.reprojectS = 0.0;
  t.traced = t.tracedBehind = 0;
  for (int pass = 0; pass < 64; ++pass) {
    ++t.stamp;
    ++t.passes;
    const uint64_t loadedBefore = t.streamer->stats().pagesLoaded;
    t.streamer->beginPass(frameStart);
    auto t0 = std::chrono::steady_clock::now();
    t.backend->renderRows(scene, shade, eyes.traced, t.stamp, t.band, 0, stereo && o.stereoFill == "reproject" ? eyes.disparityScale : 0.0f);
    t.firstEyeS += secondsSince(t0);
    t.filled = t.backend->lastFilled();
    if (stereo) {
      t0 = std::chrono::steady_clock::now();
      if (o.stereoFill == "trace") {
        t.backend->renderRows(scene, shade, eyes.right, t.stamp, t.band, 1, 0.0f);
        t.traced = uint64_t(t.band.rows()) * uint64_t(eyes.right.width);
      } else {
        const StereoCounts c = t.backend->reprojectRows(scene, eyes.right, t.stamp, t.band, o.stereo);
        t.traced = c.traced;
        t.tracedBehind = c.behind;
        t.reprojectS += c.reprojectS;
      }
      t.secondEyeS += secondsSince(t0);
    }
    t.missing = t.streamer->endPass(t.stamp);
    if (!complete || t.missing == 0) break;
    // the frame's pages do not all fit in the cache: nothing more can be installed
    if (pass > 0 && t.streamer->stats().pagesLoaded == loadedBefore) break;
    t.streamer->waitLoader();
  }
  t.costMs.push_back(1000.0 * (t.firstEyeS + t.secondEyeS));
}

// Every tile's passes of one frame, each tile on its own thread when there are several.
void renderFrame(std::vector<Tile>& tiles, const PlayOptions& o, const HostScene& scene, const ShadeParams& shade, const EyeCameras& eyes,
                 bool complete) {
  if (tiles.size() == 1) {
    renderTileFrame(tiles[0], o, scene, shade, eyes, complete);
    return;
  }
  std::vector<std::thread> threads;
  std::vector<std::exception_ptr> errors(tiles.size());
  for (size_t k = 0; k < tiles.size(); ++k)
    threads.emplace_back([&, k] {
      try {
        renderTileFrame(tiles[k], o, scene, shade, eyes, complete);
      } catch (...) {
        errors[k] = std::current_exception();
      }
    });
  for (auto& th : threads) th.join();
  for (auto& e : errors)
    if (e) std::rethrow_exception(e);
}

// Eye `eye` of the frame, assembled from every tile's band.
void readEye(std::vector<Tile>& tiles, int eye, int width, int height, std::vector<float>& rgba) {
  rgba.assign(size_t(width) * height * 4, 0.0f);
  for (Tile& t : tiles) t.backend->readRows(rgba, eye, t.band, width);
}

// Left and right side by side: one image twice as wide.
std::vector<float> sideBySide(const std::vector<float>& left, const std::vector<float>& right, int width, int height) {
  std::vector<float> out(size_t(width) * height * 8);
  for (int y = 0; y < height; ++y) {
    std::copy_n(left.begin() + size_t(y) * width * 4, size_t(width) * 4, out.begin() + size_t(y) * width * 8);
    std::copy_n(right.begin() + size_t(y) * width * 4, size_t(width) * 4, out.begin() + size_t(y) * width * 8 + size_t(width) * 4);
  }
  return out;
}

StreamStats sumStats(const std::vector<Tile>& tiles) {
  StreamStats s;
  for (const Tile& t : tiles) {
    const StreamStats& a = t.streamer->stats();
    s.pagesUsed += a.pagesUsed, s.pagesMissed += a.pagesMissed, s.pagesLoaded += a.pagesLoaded, s.bytesLoaded += a.bytesLoaded, s.bytesRead += a.bytesRead;
    s.pagesDeferred += a.pagesDeferred, s.corruptPages += a.corruptPages, s.loadSeconds += a.loadSeconds, s.evictions += a.evictions;
  }
  return s;
}

std::vector<Band> bandsOf(const std::vector<Tile>& tiles) {
  std::vector<Band> b;
  for (const Tile& t : tiles) b.push_back(t.band);
  return b;
}

double mean(const std::vector<double>& v) {
  double s = 0.0;
  for (double x : v) s += x;
  return v.empty() ? 0.0 : s / double(v.size());
}

// The level of detail statistic (cone.h countVoxelFootprint): shading segments by their voxel's
// width in pixels, and the largest.
nlohmann::json voxelPixelsReport(const WorkCounters& work) {
  float maxRatio = 0.0f;
  const uint32_t bits = uint32_t(work.maxVoxelPixelsBits);
  std::memcpy(&maxRatio, &bits, sizeof maxRatio);
  uint64_t n = 0;
  for (uint64_t c : work.voxelPixels) n += c;
  return {{"segments", n},
          {"at_most_1", work.voxelPixels[0]},
          {"at_most_1_5", work.voxelPixels[1]},
          {"at_most_4", work.voxelPixels[2]},
          {"above_4", work.voxelPixels[3]},
          {"fraction_above_1_5", n ? double(work.voxelPixels[2] + work.voxelPixels[3]) / double(n) : 0.0},
          {"max", maxRatio}};
}

nlohmann::json workReport(const WorkCounters& work, uint64_t passes) {
  return {{"passes", passes},
          {"cones", work.cones},
          {"primary_steps", work.primarySteps},
          {"shaded_samples", work.shadedSamples},
          {"segments", work.segments},
          {"descents", work.descents},
          {"brick_samples", work.brickSamples},
          {"shadow_cones", work.shadowCones},
          {"shadow_steps", work.shadowSteps},
          {"shadow_map_lookups", work.shadowMapLookups},
          {"shadow_map_steps", work.shadowMapSteps},
          {"held_segments", work.heldSegments},
          {"empty_steps", work.emptySteps},
          {"zero_brick_samples", work.zeroBrickSamples},
          {"empty_block_skips", work.emptyBlockSkips},
          {"hit_drops", work.hitDrops},
          {"hit_rewinds", work.hitRewinds},
          {"far_steps", work.farSteps},
          {"table_descents", work.tableDescents},
          {"voxel_px", voxelPixelsReport(work)}};
}

// The report of a run (frame times, cache and streaming statistics, the scene's light, the bands).
nlohmann::json playReport(const PlayOptions& o, const CanopyFile& file, const HostScene& scene, const std::vector<Tile>& tiles,
                          const ShadeParams& shade, const std::vector<double>& frameMs, std::chrono::steady_clock::time_point t0,
                          double firstCompleteS, uint64_t coldStartBytes, uint32_t slots) {
  const StreamStats st = sumStats(tiles);
  const double total = secondsSince(t0);
  uint64_t passes = 0;
  for (const Tile& t : tiles) passes += t.passes;
  nlohmann::json r;
  r["input"] = o.input;
  r["output"] = o.output;
  r["device"] = tiles[0].backend->name();
  r["size"] = {o.width, o.height};
  r["frames"] = o.frames;
  r["passes"] = passes;
  r["frame_ms_median"] = percentile(frameMs, 0.5);
  r["frame_ms_p95"] = percentile(frameMs, 0.95);
  r["frame_ms"] = frameMs;
  r["first_complete_frame_s"] = firstCompleteS;  // -1: no frame was complete
  const uint64_t lookups = st.pagesUsed + st.pagesMissed;
  r["cache_hit_rate"] = lookups ? double(st.pagesUsed) / double(lookups) : 1.0;
  r["cache_slots"] = slots;  // per band
  r["loader_threads"] = loaderThreadsFor(o.loaderThreads, int(tiles.size()));  // per band
  r["cache_mb"] = double(uint64_t(slots) * file.header().pageBytes) / (1024.0 * 1024.0);
  r["scene_page_mb"] = double(scene.brickPageBytes + scene.lightPageBytes + scene.haarPageBytes) / (1024.0 * 1024.0);
  r["light_page_mb"] = double(scene.lightPageBytes) / (1024.0 * 1024.0);
  r["haar_page_mb"] = double(scene.haarPageBytes) / (1024.0 * 1024.0);
  r["light"] = o.exactLight ? "exact" : "fast";
  r["lit_models"] = scene.litModels;
  // The coarse scene light: 0 none, 1 (B00: one static factor), 19 (B00 on the ambient term, the
  // sun's bases, relit per frame, on the scattered sun term).
  r["scene_light_bases"] = scene.lightBases;
  // The LB sun bases: scattered light only (kCanopyModelScatteredSun), or beam included (counted twice).
  r["sun_bases"] = scene.litModels == 0 ? "none"
                   : scene.totalSunModels == 0 ? "scattered"
                   : scene.totalSunModels == scene.litModels ? "total" : "mixed";
  r["pages_streamed"] = st.pagesLoaded;
  r["mb_streamed"] = double(st.bytesLoaded) / (1024.0 * 1024.0);
  // what those pages took in the file (their stored bytes: less than mb_streamed with compressed pages)
  r["file_mb_read"] = double(st.bytesRead) / (1024.0 * 1024.0);
  r["cold_start_mb"] = double(coldStartBytes) / (1024.0 * 1024.0);
  // the streaming rate of the cold start: what the first complete frame needed, over its time
  // (open, scene build, every pass and every page read and upload included)
  r["cold_start_mb_per_s"] = firstCompleteS > 0 ? double(coldStartBytes) / (1024.0 * 1024.0) / firstCompleteS : 0.0;
  r["stream_mb_per_s"] = total > 0 ? double(st.bytesLoaded) / (1024.0 * 1024.0) / total : 0.0;
  r["read_mb_per_s"] = st.loadSeconds > 0 ? double(st.bytesLoaded) / (1024.0 * 1024.0) / st.loadSeconds : 0.0;
  r["pages_deferred"] = st.pagesDeferred;
  r["evictions"] = st.evictions;
  r["corrupt_pages"] = st.corruptPages;
  r["seconds"] = total;
  r["shadows"] = shade.shadows == kShadowsOff ? "off" : o.shadowMethod;
  if (shade.ground)
    r["ground"] = {{"y", shade.groundY}, {"from", o.ground == "auto" ? "auto" : "option"}, {"albedo", {shade.groundAlbedo[0], shade.groundAlbedo[1], shade.groundAlbedo[2]}}};
  else
    r["ground"] = nullptr;
  if (shade.farStart >= 0.0f && !scene.empty) {
    const FarFieldView& f = scene.far;
    r["far_field"] = {{"dim", {f.dim[0], f.dim[1], f.dim[2]}},
                      {"voxel", f.voxel},
                      {"from", shade.farStart > 0.0f ? nlohmann::json(shade.farStart) : nlohmann::json("auto")}};
  } else {
    r["far_field"] = nullptr;
  }
  if (shade.shadows == kShadowsMap) {
    const ShadowMapView& m = tiles[0].backend->lastShadowMap();
    r["shadow_map"] = {{"dim", {m.dim[0], m.dim[1], m.dim[2]}}, {"voxel", m.voxel}};
  }
  // The bands (rows of the last frame) and each one's render time per frame.
  nlohmann::json bands = nlohmann::json::array();
  for (const Tile& t : tiles)
    bands.push_back({{"device", t.device >= 0 ? "cuda:" + std::to_string(t.device) : std::string("cpu")},
                     {"rows", {t.band.y0, t.band.y1}},
                     {"ms_median", percentile(t.costMs, 0.5)}});
  r["bands"] = bands;
  return r;
}

void logSummary(const PlayOptions& o, const nlohmann::json& r, const StreamStats& st, const std::string& backendName) {
  char line[512];
  std::snprintf(line, sizeof(line),
                "canopy-play: %d frame(s) %dx%d on %s: median %.2f ms, p95 %.2f ms; cache hit rate %.1f%%; streamed %llu pages "
                "(%.1f MB, %.1f MB/s)%s",
                o.frames, o.width, o.height, backendName.c_str(), double(r["frame_ms_median"]), double(r["frame_ms_p95"]),
                100.0 * double(r["cache_hit_rate"]), static_cast<unsigned long long>(st.pagesLoaded), double(r["mb_streamed"]),
                double(r["stream_mb_per_s"]),
                st.corruptPages ? (", " + std::to_string(st.corruptPages) + " corrupt page(s) skipped").c_str() : "");
  logInfo(line);
  if (r.contains("adaptive")) {
    const bool autoOn = r["adaptive"]["option"] == "auto";
    std::snprintf(line, sizeof(line), "canopy-play: adaptive sampling (tolerance %g%s): %.1f%% of the pixels traced", double(r["adaptive"]["tolerance"]),
                  autoOn ? ", auto at this frame size; --adaptive off traces every pixel" : "", 100.0 * double(r["adaptive"]["traced_fraction_mean"]));
    logInfo(line);
  }
  if (r.contains("stereo")) {
    const auto& s = r["stereo"];
    std::snprintf(line, sizeof(line),
                  "canopy-play: stereo (%s): second eye %.2f ms median (%.2fx the first eye; reprojection %.2f ms), %.1f%% of its pixels "
                  "traced (%.1f%% only behind a reprojected front)",
                  std::string(s["fill"]).c_str(), double(s["second_eye_ms_median"]), double(s["second_over_first"]),
                  double(s["reproject_ms_median"]),
                  100.0 * double(s["traced_fraction_mean"]), 100.0 * double(s["traced_behind_fraction_mean"]));
    logInfo(line);
  }
}

// The frame loop's record: frame times, stereo's per-eye times and traced fractions, the first
// complete frame.
struct FrameLog {
  std::vector<double> frameMs, firstEyeMs, secondEyeMs, reprojectMs, tracedFraction, behindFraction;
  std::vector<double> adaptiveFraction;  // --adaptive: the fraction of the frame's pixels traced
  float adaptive = 0.0f;                 // the run's adaptive sampling tolerance (adaptiveTolerance; 0: off)
  double firstCompleteS = -1.0;
  uint64_t coldStartBytes = 0;  // streamed by the first complete frame
};

// One band per renderer (or --tiles bands over them, round robin), each with its own cache.
std::vector<Tile> makeTiles(const PlayOptions& o, const Device& device, const CanopyFile& file, const HostScene& scene, uint32_t slots,
                            int tileH) {
  const std::vector<int> devices = deviceList(device);
  const std::vector<Band> bands0 = equalBands(o.height, o.tiles > 0 ? o.tiles : int(devices.size()), tileH);
  std::vector<Tile> tiles(bands0.size());
  for (size_t k = 0; k < tiles.size(); ++k) {
    Tile& t = tiles[k];
    t.device = devices[k % devices.size()];
    t.band = bands0[k];
    t.backend = t.device >= 0 ? makeCudaBackend(scene, slots, t.device) : makeCpuBackend(scene, slots);
    t.streamer = std::make_unique<Streamer>(file, *t.backend, slots, std::min<uint32_t>(o.stagingPages, std::max<uint32_t>(slots, 1)),
                                            loaderThreadsFor(o.loaderThreads, int(bands0.size())));
  }
  return tiles;
}

// Records a rendered frame's times, stereo figures and completeness; returns each band's cost (the
// next frame's balance).
std::vector<double> recordFrame(const PlayOptions& o, const std::vector<Tile>& tiles, std::chrono::steady_clock::time_point t0, FrameLog& log) {
  uint32_t missing = 0;
  double first = 0.0, second = 0.0, reproject = 0.0;
  uint64_t traced = 0, behind = 0, filled = 0;
  std::vector<double> cost;
  for (const Tile& t : tiles) {
    missing += t.missing;
    filled += t.filled;
    first = std::max(first, t.firstEyeS), second = std::max(second, t.secondEyeS), reproject = std::max(reproject, t.reprojectS);
    traced += t.traced;
    behind += t.tracedBehind;
    cost.push_back(t.firstEyeS + t.secondEyeS);
  }
  if (o.stereoIpd > 0.0f) {
    log.firstEyeMs.push_back(1000.0 * first);
    log.secondEyeMs.push_back(1000.0 * second);
    log.reprojectMs.push_back(1000.0 * reproject);
    log.tracedFraction.push_back(double(traced) / (double(o.width) * o.height));
    log.behindFraction.push_back(double(behind) / (double(o.width) * o.height));
  }
  if (log.adaptive > 0.0f) log.adaptiveFraction.push_back(1.0 - double(filled) / (double(o.width) * o.height));
  if (missing == 0 && log.firstCompleteS < 0.0) {
    log.firstCompleteS = secondsSince(t0);
    log.coldStartBytes = sumStats(tiles).bytesLoaded;
  }
  return cost;
}

// Writes frame f (-o, and --right-output for stereo's right eye; side by side without it).
void writeFrame(const PlayOptions& o, int f, const std::vector<float>& image, const std::vector<float>& right, WrittenFrames& written) {
  const std::string path = frameFileName(o.output, f, o.frames);
  if (o.stereoIpd > 0.0f && o.rightOutput.empty()) {
    writeImage(path, sideBySide(image, right, o.width, o.height), 2 * o.width, o.height, o.background);
  } else {
    writeImage(path, image, o.width, o.height, o.background);
  }
  written.add(path);
  if (!o.rightOutput.empty()) {
    const std::string rpath = frameFileName(o.rightOutput, f, o.frames);
    writeImage(rpath, right, o.width, o.height, o.background);
    written.add(rpath);
  }
}

// The report's "stereo" object.
nlohmann::json stereoReport(const PlayOptions& o, const FrameLog& log) {
  const double first = percentile(log.firstEyeMs, 0.5), second = percentile(log.secondEyeMs, 0.5);
  return {{"ipd", o.stereoIpd},
          {"fill", o.stereoFill},
          {"max_spread_px", o.stereo.maxSpread},
          {"solid_alpha", o.stereo.solidAlpha},
          {"layout", o.rightOutput.empty() ? "side-by-side" : "separate"},
          {"traced_fraction_mean", mean(log.tracedFraction)},
          {"traced_behind_fraction_mean", mean(log.behindFraction)},
          {"first_eye_ms_median", first},
          {"second_eye_ms_median", second},
          {"second_over_first", first > 0 ? second / first : 0.0},
          {"reproject_ms_median", percentile(log.reprojectMs, 0.5)},
          {"traced_fraction", log.tracedFraction},
          {"second_eye_ms", log.secondEyeMs}};
}

}  // namespace

int loaderThreadsFor(int requested, int bands) {
  if (requested > 0) return requested;
  const int host = int(std::thread::hardware_concurrency());
  return std::clamp(host / std::max(bands, 1), 2, 16);
}

nlohmann::json play(const PlayOptions& o, const Device& device, std::vector<float>* lastImage, std::vector<float>* lastRight) {
  const auto t0 = std::chrono::steady_clock::now();
  validateOptions(o);
  const bool stereo = o.stereoIpd > 0.0f;

  const CanopyFile file = CanopyFile::open(o.input);
  HostScene scene = buildScene(file);
  if (o.descentTable) addDescentTables(scene);
  const std::vector<FrameSetup> plan = framePlan(o, scene);
  const uint64_t cacheBytes = uint64_t(o.cacheMb * 1024.0 * 1024.0);
  const uint32_t slots = uint32_t(std::min<uint64_t>(std::max<uint64_t>(cacheBytes / file.header().pageBytes, 1), std::max<uint32_t>(file.pageCount(), 1)));
  const int tileH = 32 / o.warpTileWidth;
  std::vector<Tile> tiles = makeTiles(o, device, file, scene, slots, tileH);
  const std::string backendName = tiles[0].backend->name();
  logInfo("canopy-play: " + o.input + ": " + std::to_string(file.modelCount()) + " model(s), " + std::to_string(file.instanceCount()) +
          " instance(s), " + std::to_string(file.pageCount()) + " pages; cache " + std::to_string(slots) + " pages (" +
          std::to_string(uint64_t(slots) * file.header().pageBytes >> 20) + " MiB) on " + backendName +
          (tiles.size() > 1 ? " x " + std::to_string(tiles.size()) + " bands, a cache each" : ""));

  ShadeParams shade = shadeParams(o);
  setGround(o, scene, shade);
  WorkCounters work{};
  const float adaptive = adaptiveTolerance(o);
  for (Tile& t : tiles) {
    if (o.countWork && tiles.size() == 1) t.backend->countWork(&work);
    t.backend->setPixelTile(o.warpTileWidth, tileH);
    t.backend->setPixelOccupancy(o.pixelMinBlocks);
    t.backend->setStereoHoles(o.stereoHoleOrder == "tile" ? kHoleOrderTile : kHoleOrderKind, o.stereoHoleBlocks);
    t.backend->setAdaptive(adaptive);
  }

  FrameLog log;
  log.adaptive = adaptive;
  std::vector<float> image, right;
  Progress progress("canopy-play", o.frames);
  WrittenFrames written;
  for (int f = 0; f < o.frames; ++f) {
    const FrameSetup& fs = plan[size_t(f)];
    shade.toSun = fs.toSun;
    scene.setSun(fs.toSun);
    const EyeCameras eyes = eyeCameras(o, fs.camera);
    const auto tf = std::chrono::steady_clock::now();
    renderFrame(tiles, o, scene, shade, eyes, o.converge || (o.warmStart && f == 0));
    log.frameMs.push_back(1000.0 * secondsSince(tf));
    const std::vector<double> cost = recordFrame(o, tiles, t0, log);
    if (!o.output.empty() || lastImage) {
      readEye(tiles, 0, o.width, o.height, image);
      if (stereo) readEye(tiles, 1, o.width, o.height, right);
    }
    if (!o.output.empty()) writeFrame(o, f, image, right, written);
    if (tiles.size() > 1) {
      const std::vector<Band> next = balanceBands(bandsOf(tiles), cost, o.height, tileH);
      for (size_t k = 0; k < tiles.size(); ++k) tiles[k].band = next[k];
    }
    progress.add();
  }
  written.keep();
  progress.done();

  nlohmann::json r = playReport(o, file, scene, tiles, shade, log.frameMs, t0, log.firstCompleteS, log.coldStartBytes, slots);
  if (stereo) r["stereo"] = stereoReport(o, log);
  if (adaptive > 0.0f)
    r["adaptive"] = {{"tolerance", adaptive}, {"option", o.adaptive}, {"traced_fraction_mean", mean(log.adaptiveFraction)}, {"traced_fraction", log.adaptiveFraction}};
  if (o.countWork && backendName == "cpu" && tiles.size() == 1)
    r["work"] = workReport(work, tiles[0].passes);
  logSummary(o, r, sumStats(tiles), backendName);
  if (lastImage) *lastImage = image;
  if (lastRight) *lastRight = right;
  return r;
}

}  // namespace canopy::play
