// pathtrace.cpp: see pathtrace.h.
#include "tests/reference/pathtrace.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>

#include "canopy/parallel.h"

namespace canopy::reference {
namespace {

constexpr float kInf = std::numeric_limits<float>::infinity();
constexpr float kPi = 3.14159265358979323846f;

// ---- volumes ------------------------------------------------------------------------------------

float cellDensity(const Volume& v, int x, int y, int z) {
  if (x < 0 || y < 0 || z < 0 || x >= v.dim[0] || y >= v.dim[1] || z >= v.dim[2]) return 0.0f;
  return v.density[v.cell(x, y, z)];
}

// Trilinear corners of relative index point q (cell centres at integers).
struct Corners {
  int i0[3];
  float f[3];
};
Corners corners(const float q[3]) {
  Corners c;
  for (int a = 0; a < 3; ++a) {
    const float fl = std::floor(q[a]);
    c.i0[a] = int(fl);
    c.f[a] = q[a] - fl;
  }
  return c;
}
float cornerWeight(const Corners& c, int k) {
  return ((k & 1) ? c.f[0] : 1.0f - c.f[0]) * ((k & 2) ? c.f[1] : 1.0f - c.f[1]) * ((k & 4) ? c.f[2] : 1.0f - c.f[2]);
}

float densityAt(const Volume& v, const float q[3]) {
  const Corners c = corners(q);
  float r = 0.0f;
  for (int k = 0; k < 8; ++k) {
    const float w = cornerWeight(c, k);
    if (w == 0.0f) continue;
    r += w * cellDensity(v, c.i0[0] + (k & 1), c.i0[1] + ((k >> 1) & 1), c.i0[2] + ((k >> 2) & 1));
  }
  return r;
}

// Density-weighted trilinear albedo (canopySampleBrick's weighting).
void albedoAt(const Volume& v, const float q[3], float out[3]) {
  const Corners c = corners(q);
  float sw = 0.0f, acc[3] = {0, 0, 0};
  for (int k = 0; k < 8; ++k) {
    const int x = c.i0[0] + (k & 1), y = c.i0[1] + ((k >> 1) & 1), z = c.i0[2] + ((k >> 2) & 1);
    const float w = cornerWeight(c, k) * cellDensity(v, x, y, z);
    if (w <= 0.0f) continue;
    const float* a = &v.albedo[3 * v.cell(x, y, z)];
    for (int ch = 0; ch < 3; ++ch) acc[ch] += w * a[ch];
    sw += w;
  }
  for (int ch = 0; ch < 3; ++ch) out[ch] = sw > 0.0f ? acc[ch] / sw : 0.0f;
}

// The wood fraction of the cell that a collision at q belongs to: the summed medium's corner k
// scatters with probability w_k rho_k / rho(q) (the trilinear density is a sum of 8 media).
float pickWood(const Volume& v, const float q[3], float u) {
  const Corners c = corners(q);
  float w[8], sum = 0.0f;
  for (int k = 0; k < 8; ++k) {
    w[k] = cornerWeight(c, k) * cellDensity(v, c.i0[0] + (k & 1), c.i0[1] + ((k >> 1) & 1), c.i0[2] + ((k >> 2) & 1));
    sum += w[k];
  }
  float target = u * sum;
  int pick = -1;
  for (int k = 0; k < 8; ++k) {
    if (w[k] <= 0.0f) continue;
    pick = k;
    if (target < w[k]) break;
    target -= w[k];
  }
  if (pick < 0) return 0.0f;
  return v.wood[v.cell(c.i0[0] + (pick & 1), c.i0[1] + ((pick >> 1) & 1), c.i0[2] + ((pick >> 2) & 1))];
}

// ---- one instance along a world ray -------------------------------------------------------------

struct InstanceRay {
  float qo[3], qd[3];  // relative index coordinates q(t) = qo + t qd (t: world length along the unit ray)
  float t0, t1;        // inside the lattice box [-0.5, dim - 0.5]
  float perCell;       // extinction per world unit at density 1: sigma / cellWorld
};

bool instanceRay(const Medium& m, const Instance& in, V3 o, V3 d, float tMax, InstanceRay& r, float sigma = -1.0f) {
  const Volume& v = m.volumes[in.volume];
  const double* A = in.worldToIndex;
  const double od[3] = {o.x, o.y, o.z}, dd[3] = {d.x, d.y, d.z};
  r.t0 = 0.0f;
  r.t1 = tMax;
  for (int a = 0; a < 3; ++a) {
    const double po = A[4 * a] * od[0] + A[4 * a + 1] * od[1] + A[4 * a + 2] * od[2] + A[4 * a + 3] - v.min[a];
    const double pd = A[4 * a] * dd[0] + A[4 * a + 1] * dd[1] + A[4 * a + 2] * dd[2];
    r.qo[a] = float(po);
    r.qd[a] = float(pd);
    const double lo = -0.5, hi = v.dim[a] - 0.5;
    if (std::fabs(pd) < 1e-30) {
      if (po < lo || po > hi) return false;
      continue;
    }
    double ta = (lo - po) / pd, tb = (hi - po) / pd;
    if (ta > tb) std::swap(ta, tb);
    r.t0 = std::max(r.t0, float(ta));
    r.t1 = std::min(r.t1, float(tb));
  }
  r.perCell = (sigma >= 0.0f ? sigma : m.sigma) / in.cellWorld;
  return r.t0 < r.t1;
}

// Calls f(tEnter, tExit, blockMaxDensity) for the majorant blocks along the ray, in order, until f
// returns false or the ray leaves the box.
template <class F>
void walkBlocks(const Volume& v, const InstanceRay& r, F&& f) {
  int idx[3], step[3];
  float tNext[3], tDelta[3];
  const float tStart = r.t0;
  for (int a = 0; a < 3; ++a) {
    const float g = (r.qo[a] + tStart * r.qd[a] + 0.5f) / float(kBlock);
    idx[a] = std::clamp(int(std::floor(g)), 0, v.blocks[a] - 1);
    if (r.qd[a] > 0.0f) {
      step[a] = 1;
      tNext[a] = (float((idx[a] + 1) * kBlock) - 0.5f - r.qo[a]) / r.qd[a];
      tDelta[a] = float(kBlock) / r.qd[a];
    } else if (r.qd[a] < 0.0f) {
      step[a] = -1;
      tNext[a] = (float(idx[a] * kBlock) - 0.5f - r.qo[a]) / r.qd[a];
      tDelta[a] = -float(kBlock) / r.qd[a];
    } else {
      step[a] = 0;
      tNext[a] = kInf;
      tDelta[a] = kInf;
    }
  }
  float t = tStart;
  while (t < r.t1) {
    const int a = tNext[0] < tNext[1] ? (tNext[0] < tNext[2] ? 0 : 2) : (tNext[1] < tNext[2] ? 1 : 2);
    const float tExit = std::min(tNext[a], r.t1);
    const float mx = v.blockMax[size_t(idx[0]) + size_t(v.blocks[0]) * (size_t(idx[1]) + size_t(v.blocks[1]) * size_t(idx[2]))];
    if (tExit > t && !f(t, tExit, mx)) return;
    t = std::max(t, tExit);
    idx[a] += step[a];
    tNext[a] += tDelta[a];
    if (idx[a] < 0 || idx[a] >= v.blocks[a]) return;
  }
}

void pointAt(const InstanceRay& r, float t, float q[3]) {
  for (int a = 0; a < 3; ++a) q[a] = r.qo[a] + t * r.qd[a];
}

// Delta tracking in one instance: the first real collision's t (kInf: none before t1).
float deltaTrack(const Volume& v, const InstanceRay& r, Rng& rng) {
  float hit = kInf;
  walkBlocks(v, r, [&](float ta, float tb, float mx) {
    if (!(mx > 0.0f)) return true;
    const float M = mx * r.perCell;
    float t = ta;
    for (;;) {
      t -= std::log1p(-rng.next()) / M;
      if (t >= tb) return true;
      float q[3];
      pointAt(r, t, q);
      if (rng.next() * mx < densityAt(v, q)) {
        hit = t;
        return false;
      }
    }
  });
  return hit;
}

// Ratio tracking in one instance: multiplies T by the estimate (roulette below 0.05).
void ratioTrack(const Volume& v, const InstanceRay& r, Rng& rng, float& T) {
  walkBlocks(v, r, [&](float ta, float tb, float mx) {
    if (!(mx > 0.0f)) return true;
    const float M = mx * r.perCell;
    float t = ta;
    for (;;) {
      t -= std::log1p(-rng.next()) / M;
      if (t >= tb) return true;
      float q[3];
      pointAt(r, t, q);
      T *= 1.0f - densityAt(v, q) / mx;
      if (T < 0.05f) {
        if (rng.next() < 0.5f) {
          T = 0.0f;
          return false;
        }
        T *= 2.0f;
      }
    }
  });
}

struct Hit {
  float t = kInf;
  uint32_t instance = 0;
  float q[3];
};

// The summed medium's first collision along o + t d: the nearest of the instances' own.
// sigma >= 0 replaces the medium's extinction scale (TraceOptions::indirectSigma).
bool firstCollision(const Medium& m, V3 o, V3 d, Rng& rng, Hit& h, float sigma = -1.0f) {
  h.t = kInf;
  for (uint32_t i = 0; i < m.instances.size(); ++i) {
    InstanceRay r;
    if (!instanceRay(m, m.instances[i], o, d, h.t, r, sigma)) continue;
    const float t = deltaTrack(m.volumes[m.instances[i].volume], r, rng);
    if (t < h.t) {
      h.t = t;
      h.instance = i;
      pointAt(r, t, h.q);
    }
  }
  return h.t < kInf;
}

// ---- directions ---------------------------------------------------------------------------------

V3 uniformSphere(Rng& rng) {
  const float z = 1.0f - 2.0f * rng.next();
  const float r = std::sqrt(std::max(0.0f, 1.0f - z * z));
  const float phi = 2.0f * kPi * rng.next();
  return V3{r * std::cos(phi), r * std::sin(phi), z};
}

// Henyey-Greenstein density of the cosine mu between the light's travel directions before and
// after the event (per steradian).
float hgPhase(float g, float mu) {
  const float denom = 1.0f + g * g - 2.0f * g * mu;
  return (1.0f - g * g) / (4.0f * kPi * denom * std::sqrt(denom));
}

// A direction whose cosine with `axis` follows HG(g) (|g| < 1).
V3 sampleHg(float g, V3 axis, Rng& rng) {
  const float u = rng.next();
  float mu;
  if (std::fabs(g) < 1e-3f) {
    mu = 1.0f - 2.0f * u;
  } else {
    const float s = (1.0f - g * g) / (1.0f - g + 2.0f * g * u);
    mu = (1.0f + g * g - s * s) / (2.0f * g);
  }
  mu = std::clamp(mu, -1.0f, 1.0f);
  const float st = std::sqrt(std::max(0.0f, 1.0f - mu * mu));
  const float phi = 2.0f * kPi * rng.next();
  const V3 helper = std::fabs(axis.x) > 0.9f ? V3{0, 1, 0} : V3{1, 0, 0};
  const V3 b1 = play::normalize(play::cross(helper, axis));
  const V3 b2 = play::cross(axis, b1);
  return play::normalize(b1 * (st * std::cos(phi)) + b2 * (st * std::sin(phi)) + axis * mu);
}

float ratioTrackWithSigma(const Medium& m, V3 o, V3 d, float tMax, Rng& rng, float sigma) {
  float T = 1.0f;
  for (const Instance& in : m.instances) {
    InstanceRay r;
    if (!instanceRay(m, in, o, d, tMax, r, sigma)) continue;
    ratioTrack(m.volumes[in.volume], r, rng, T);
    if (T == 0.0f) break;
  }
  return T;
}

float sunTransmittance(const Medium& m, V3 x, V3 toSun, Rng& rng, float sigma = -1.0f) {
  return ratioTrackWithSigma(m, x, toSun, kInf, rng, sigma);
}

}  // namespace

// ---- public -------------------------------------------------------------------------------------

void Volume::finish() {
  for (int a = 0; a < 3; ++a) blocks[a] = (dim[a] + kBlock - 1) / kBlock;
  blockMax.assign(size_t(blocks[0]) * blocks[1] * blocks[2], 0.0f);
  for (int bz = 0; bz < blocks[2]; ++bz)
    for (int by = 0; by < blocks[1]; ++by)
      for (int bx = 0; bx < blocks[0]; ++bx) {
        // a trilinear sample inside block b (q in [bB - 0.5, bB + B - 0.5)) reads cells bB - 1 .. bB + B
        float mx = 0.0f;
        for (int z = bz * kBlock - 1; z <= bz * kBlock + kBlock; ++z)
          for (int y = by * kBlock - 1; y <= by * kBlock + kBlock; ++y)
            for (int x = bx * kBlock - 1; x <= bx * kBlock + kBlock; ++x) mx = std::max(mx, cellDensity(*this, x, y, z));
        blockMax[size_t(bx) + size_t(blocks[0]) * (size_t(by) + size_t(blocks[1]) * size_t(bz))] = mx;
      }
}

Rng::Rng(uint64_t seed, uint64_t stream) {
  // PCG32 (O'Neill 2014): the stream picks the increment, the seed the start
  uint64_t s = seed * 0x9E3779B97F4A7C15ull ^ (stream + 0x632BE59BD9B4E019ull);
  s ^= s >> 31;
  s *= 0xBF58476D1CE4E5B9ull;
  s ^= s >> 27;
  inc_ = (stream << 1u) | 1u;
  state_ = 0;
  next();
  state_ += s;
  next();
}

float Rng::next() {
  const uint64_t old = state_;
  state_ = old * 6364136223846793005ull + inc_;
  const uint32_t xorshifted = uint32_t(((old >> 18u) ^ old) >> 27u);
  const uint32_t rot = uint32_t(old >> 59u);
  const uint32_t r = (xorshifted >> rot) | (xorshifted << ((32 - rot) & 31));
  return float(r >> 8) * (1.0f / 16777216.0f);
}

float ratioTrackTransmittance(const Medium& m, V3 o, V3 d, float tMax, Rng& rng) { return ratioTrackWithSigma(m, o, d, tMax, rng, -1.0f); }

double quadratureTransmittance(const Medium& m, V3 o, V3 d, double tMax, double stepCells) {
  double tau = 0.0;
  for (const Instance& in : m.instances) {
    InstanceRay r;
    if (!instanceRay(m, in, o, d, float(tMax), r)) continue;
    const double dt = stepCells * in.cellWorld;
    const int n = std::max(1, int(std::ceil((r.t1 - r.t0) / dt)));
    const double h = double(r.t1 - r.t0) / n;
    for (int k = 0; k < n; ++k) {
      float q[3];
      pointAt(r, float(r.t0 + (k + 0.5) * h), q);
      tau += double(densityAt(m.volumes[in.volume], q)) * r.perCell * h;
    }
  }
  return std::exp(-tau);
}

float extinctionAt(const Medium& m, V3 x) {
  float k = 0.0f;
  for (const Instance& in : m.instances) {
    const Volume& v = m.volumes[in.volume];
    const double* A = in.worldToIndex;
    float q[3];
    bool inside = true;
    for (int a = 0; a < 3; ++a) {
      q[a] = float(A[4 * a] * x.x + A[4 * a + 1] * x.y + A[4 * a + 2] * x.z + A[4 * a + 3] - v.min[a]);
      inside = inside && q[a] >= -0.5f && q[a] <= float(v.dim[a]) - 0.5f;
    }
    if (inside) k += densityAt(v, q) * m.sigma / in.cellWorld;
  }
  return k;
}

namespace {

// The derived LB scattering parameters (pathtrace.h, Medium::lb).
struct LbScatter {
  float leafAlbedo[3], woodBack[3], woodIso[3];
  float qBack;     // the probability of picking a wood event's back-scattered part
  bool woodDelta;  // wood's scattered part is a delta (g = +-1)
};

LbScatter lbScatter(const LbMaterial& lb) {
  LbScatter k;
  for (int c = 0; c < 3; ++c) {
    const float st = lb.sigmaA[c] + lb.sigmaS[c];
    k.leafAlbedo[c] = lb.sigmaS[c] / st;
    k.woodBack[c] = lb.sigmaS[c] / st;
    k.woodIso[c] = lb.sigmaA[c] / st;
  }
  k.qBack = (k.woodBack[0] + k.woodBack[1] + k.woodBack[2]) / 3.0f;
  k.woodDelta = std::fabs(lb.gWood) > 0.999f;
  return k;
}

// One camera path from o along d: adds its RGB contribution to acc and returns its alpha estimate's
// transmittance (ratio tracking along the camera ray).
float tracePath(const Medium& m, const Lighting& L, V3 o, V3 d, const TraceOptions& opt, const LbScatter& k, Rng& rng, double acc[3]) {
  const LbMaterial& lb = m.lb;
  const float trans = ratioTrackTransmittance(m, o, d, kInf, rng);
  Hit h;
  if (!firstCollision(m, o, d, rng, h)) return trans;  // escaped: no background
  V3 x = o + d * h.t;
  // camera vertex: the voxel's albedo, isotropic phase
  float beta[3];
  const Volume& v0 = m.volumes[m.instances[h.instance].volume];
  albedoAt(v0, h.q, beta);
  if (!opt.noCameraSun) {
    const float Ts = opt.unshadowedSun ? 1.0f : sunTransmittance(m, x, L.toSun, rng);
    for (int c = 0; c < 3; ++c) acc[c] += beta[c] * L.sun[c] * Ts;  // (1/4pi) * 4pi sun * T
  }
  if (opt.firstVertexOnly) return trans;
  const float deepSigma = opt.indirectSigma > 0.0f ? opt.indirectSigma : m.sigma;  // the light field's medium
  // Deeper vertices: HG lobes that differ per channel. Spectral MIS at the path level (the
  // "hero wavelength" scheme, Wilkie et al. 2014): the path's directions follow one channel's
  // lobes (the hero, picked per path), and channel c's estimate is f_c / mean_k pdf_k(path),
  // the balance heuristic over the three channels' path densities. With A_c the product of
  // channel c's albedos and r_k = pdf_k(path) / pdf_hero(path): beta_c = A_c r_c / mean_k r_k,
  // at most 3 A_c (no product of per-vertex weights that could grow without bound).
  const int hero = std::min(2, int(rng.next() * 3.0f));
  double A[3] = {beta[0], beta[1], beta[2]}, r[3] = {1.0, 1.0, 1.0};
  const auto weights = [&](double out[3]) {
    const double mean = (r[0] + r[1] + r[2]) / 3.0;
    for (int c = 0; c < 3; ++c) out[c] = A[c] * r[c] / mean;
  };
  V3 dir = uniformSphere(rng);  // the camera vertex's isotropic phase: the same pdf in every channel
  for (int bounce = 1; bounce < opt.maxBounces; ++bounce) {
    double w[3];
    weights(w);
    if (!firstCollision(m, x, dir, rng, h, deepSigma)) {
      for (int c = 0; c < 3; ++c) acc[c] += w[c] * L.ambient;  // the sky
      break;
    }
    x = x + dir * h.t;
    const Volume& v = m.volumes[m.instances[h.instance].volume];
    const bool wood = pickWood(v, h.q, rng.next()) >= lb.woodThreshold;
    // light leaves this vertex travelling -dir; the sun's arrives travelling -toSun
    const float muSun = play::dot(L.toSun, dir);
    const float Ts = opt.unshadowedSun ? 1.0f : sunTransmittance(m, x, L.toSun, rng, deepSigma);
    if (!wood) {
      for (int c = 0; c < 3; ++c) acc[c] += w[c] * k.leafAlbedo[c] * hgPhase(lb.g[c], muSun) * 4.0f * kPi * L.sun[c] * Ts;
      const V3 nd = sampleHg(lb.g[hero], dir, rng);
      const float mu = play::dot(nd, dir);
      const double ph = hgPhase(lb.g[hero], mu);
      for (int c = 0; c < 3; ++c) {
        r[c] = std::min(r[c] * (double(hgPhase(lb.g[c], mu)) / ph), 1e200);
        A[c] *= k.leafAlbedo[c];
      }
      dir = nd;
    } else {
      for (int c = 0; c < 3; ++c) {
        float f = k.woodIso[c] * (1.0f / (4.0f * kPi));
        if (!k.woodDelta) f += k.woodBack[c] * hgPhase(lb.gWood, muSun);
        acc[c] += w[c] * f * 4.0f * kPi * L.sun[c] * Ts;
      }
      // the component is picked with channel-independent probabilities: r is unchanged
      if (rng.next() < k.qBack) {  // the scattered part: back (g = -1) or an HG lobe
        dir = k.woodDelta ? (lb.gWood < 0.0f ? dir * -1.0f : dir) : sampleHg(lb.gWood, dir, rng);
        for (int c = 0; c < 3; ++c) A[c] *= k.woodBack[c] / k.qBack;
      } else {  // the absorbed f_0, re-emitted isotropically
        dir = uniformSphere(rng);
        for (int c = 0; c < 3; ++c) A[c] *= k.woodIso[c] / (1.0f - k.qBack);
      }
    }
    if (bounce >= opt.minBounces) {
      weights(w);
      const double pc = std::min(0.95, std::max(w[0], std::max(w[1], w[2])));
      if (!(pc > 0.0) || rng.next() >= pc) break;
      for (int c = 0; c < 3; ++c) A[c] /= pc;
    }
  }
  return trans;
}

}  // namespace

PixelEstimate tracePixel(const Medium& m, const Lighting& L, V3 o, V3 d, const TraceOptions& opt, uint64_t pixel) {
  if (opt.spp < 1 || opt.spp > kMaxSpp) throw std::invalid_argument("reference: spp must be 1..4096");
  const LbScatter k = lbScatter(m.lb);
  double sum[3] = {0, 0, 0}, sumSq[3] = {0, 0, 0}, trans = 0.0;
  for (int s = 0; s < opt.spp; ++s) {
    Rng rng(opt.seed, pixel * uint64_t(kMaxSpp) + uint64_t(s));  // one stream per (pixel, sample)
    double acc[3] = {0, 0, 0};
    trans += tracePath(m, L, o, d, opt, k, rng, acc);
    for (int c = 0; c < 3; ++c) sum[c] += acc[c], sumSq[c] += acc[c] * acc[c];
  }
  const double n = double(opt.spp);
  PixelEstimate e;
  for (int c = 0; c < 3; ++c) {
    const double mean = sum[c] / n;
    e.rgba[c] = float(mean);
    e.variance[c] = n > 1 ? float(std::max(0.0, (sumSq[c] - n * mean * mean) / (n - 1)) / n) : 0.0f;
  }
  e.rgba[3] = float(1.0 - trans / n);
  return e;
}

std::vector<float> renderReference(const Medium& m, const Lighting& L, const play::CameraView& camera, const TraceOptions& opt,
                                   std::vector<float>* variance) {
  std::vector<float> img(size_t(camera.width) * camera.height * 4, 0.0f);
  if (variance) variance->assign(size_t(camera.width) * camera.height * 3, 0.0f);
  parallelFor(
      int64_t(camera.width) * camera.height,
      [&](int64_t i) {
        const int x = int(i % camera.width), y = int(i / camera.width);
        float fp;
        const V3 d = play::cameraRay(camera, x, y, fp);
        const PixelEstimate p = tracePixel(m, L, camera.position, d, opt, uint64_t(i));
        for (int c = 0; c < 4; ++c) img[size_t(4 * i + c)] = p.rgba[c];
        if (variance)
          for (int c = 0; c < 3; ++c) (*variance)[size_t(3 * i + c)] = p.variance[c];
      },
      4);
  return img;
}

}  // namespace canopy::reference
