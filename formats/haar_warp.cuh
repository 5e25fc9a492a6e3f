// haar_warp.cuh: chaarSampleWarp, the point sampler for the 32 lanes of a warp together (CUDA only).
//
// The per-thread sampler (chaarSample) runs a loop over the kept coefficients its footprint needs,
// and a warp runs that loop as often as its busiest lane needs: on oak_medium's light at 64^3
// (quant, 1 % RMS) the 32 lanes need 11.1 coefficients each on average but the warp iterates 30.2
// times (37 % of the lanes' work is useful; fp16 28 %). This sampler spreads the warp's terms
// evenly over its lanes instead:
//   1. each lane works out its sample's plan (the same CANOPY_HD code as the per-thread sampler:
//      footprintWeights / quantSamplePlan) and writes it to shared memory; a warp scan numbers the
//      terms of all 32 samples, lane after lane, each lane's in increasing coefficient order;
//   2. in chunks of kCapacity terms: each lane lists its terms of the chunk (coefficient, owner);
//      then lane k computes terms k, k + 32, ... (value times weight, the per-thread sampler's
//      rounded operations) into shared memory;
//   3. each lane adds its own sample's terms in order (cheap: a load and three adds per term).
// The terms are the same numbers added in the same order as in sumTerms, so the result equals
// chaarSample's bit for bit (tests/haar/test_haar_cuda.cpp checks it on every precision).
//
// Contract: all 32 lanes of the warp call it together (converged), with the same `base`; lanes
// without a sample pass active = false (they return zero). `s` is this warp's scratch, in shared
// memory: e.g. `__shared__ ChaarWarpScratch<> scratch[kWarpsPerBlock]` and scratch[threadIdx.x / 32].
#pragma once
#include <cstdint>
#include <type_traits>

#include "formats/haar_view.h"

namespace canopy::haar {

template <uint32_t kCapacity = 256>
struct ChaarWarpScratch {
  static_assert(kCapacity % 32 == 0, "whole rounds of 32 terms");
  static constexpr uint32_t capacity = kCapacity;
  float weight[32][13];        // per sample: wx[4], wy[4], wz[4] (a 13-word stride: no bank conflicts)
  uint4 brick[32];             // per sample: maskLo, maskHi, and the brick's two words for its values
  uint16_t item[kCapacity];    // the chunk's terms: coefficient | owner lane << 6
  float4 term[kCapacity];      // the chunk's terms' values (rgb)
};

namespace warp_detail {

__device__ __forceinline__ uint32_t laneId() {
  uint32_t lane;
  asm("mov.u32 %0, %%laneid;" : "=r"(lane));
  return lane;
}

// The kept coefficient of rank `rank` of a brick described by (a, b): quantised bricks.
struct QuantValue {
  const uint64_t* words;
  __device__ __forceinline__ Rgb operator()(uint32_t a, uint32_t b, uint32_t rank) const {
    return QuantDetails(words, b & 0xfffu, a, b >> 12)(rank, 0u);
  }
};
// ... float bricks (a = the index of the brick's first coefficient).
template <class Reader>
struct FloatValue {
  Reader read;
  __device__ __forceinline__ Rgb operator()(uint32_t a, uint32_t, uint32_t rank) const {
    return read(uint64_t(a) + rank);
  }
};

// out + the terms of this lane's sample (fw.need, in increasing c), computed by the whole warp.
template <uint32_t kCapacity, class Value>
__device__ inline Rgb warpSum(Rgb out, const FootprintWeights& fw, uint32_t maskLo, uint32_t maskHi, uint32_t a,
                              uint32_t b, const Value& value, ChaarWarpScratch<kCapacity>& s) {
  const uint32_t lane = laneId();
  uint32_t restLo = uint32_t(fw.need), restHi = uint32_t(fw.need >> 32);
  const uint32_t n = popcount32(restLo) + popcount32(restHi);
  uint32_t incl = n;  // inclusive scan of the lanes' term counts
#pragma unroll
  for (uint32_t d = 1; d < 32; d <<= 1) {
    const uint32_t t = __shfl_up_sync(0xffffffffu, incl, d);
    if (lane >= d) incl += t;
  }
  const uint32_t total = __shfl_sync(0xffffffffu, incl, 31);
  if (total == 0) return out;  // (warp-uniform)
  const uint32_t excl = incl - n;
#pragma unroll
  for (int k = 0; k < 4; ++k) {
    s.weight[lane][k] = fw.wx[k];
    s.weight[lane][4 + k] = fw.wy[k];
    s.weight[lane][8 + k] = fw.wz[k];
  }
  s.brick[lane] = make_uint4(maskLo, maskHi, a, b);
  uint32_t pos = excl;  // this lane's next term
  for (uint32_t chunk = 0; chunk < total; chunk += kCapacity) {
    const uint32_t end = chunk + kCapacity;
    for (; pos < end && (restLo | restHi); ++pos) {
      const bool lo = restLo != 0;
      const uint32_t c = lo ? lowestBit32(restLo) : 32u + lowestBit32(restHi);
      if (lo) restLo &= restLo - 1u;
      else restHi &= restHi - 1u;
      s.item[pos - chunk] = uint16_t(c | (lane << 6));
    }
    __syncwarp();
    const uint32_t count = min(total - chunk, kCapacity);
    for (uint32_t k = lane; k < count; k += 32) {
      const uint32_t code = s.item[k], o = code >> 6, c = code & 63u;
      const uint4 br = s.brick[o];
      const float* w = s.weight[o];
      const float wc = mulRn(mulRn(w[c & 3u], w[4u + ((c >> 2) & 3u)]), w[8u + (c >> 4)]);  // FootprintWeights(c)
      const Rgb t = weighted(value(br.z, br.w, keptRank(br.x, br.y, c)), wc);
      s.term[k] = make_float4(t.r, t.g, t.b, 0.0f);
    }
    __syncwarp();
    for (uint32_t k = max(excl, chunk), e = min(incl, end); k < e; ++k) {
      const float4 t = s.term[k - chunk];
      addTo(out, Rgb{t.x, t.y, t.z});
    }
    __syncwarp();
  }
  return out;
}

}  // namespace warp_detail

// chaarSample(v, base, x, y, z) for each lane with active = true, computed by the whole warp.
template <uint32_t kCapacity>
__device__ inline Rgb chaarSampleWarp(const ChaarView& v, int base, float x, float y, float z, bool active,
                                      ChaarWarpScratch<kCapacity>& s) {
  using namespace warp_detail;
  const BrickLookup at = locate(v, x, y, z);
  const bool live = active && at.slot != kEmptySlot;
  const uint64_t off = v.baseCoefOffset[base];
  const uint64_t r = uint64_t(base) * v.slotCount + at.slot;
  if (v.precision == Precision::Quant) {
    const uint64_t* words = static_cast<const uint64_t*>(v.coefs) + off;
    const QuantRecord rec = live ? loadQuantRecord(v.quantRecords + r) : QuantRecord{};
    QuantSamplePlan p;
    if (rec.maskLo | rec.maskHi) p = quantSamplePlan(rec, words, at.lx, at.ly, at.lz, at.fx, at.fy, at.fz);
    const Rgb sum = warpSum(p.init, p.fw, rec.maskLo, rec.maskHi, p.base, p.widths | (p.bits << 12), QuantValue{words}, s);
    return live ? quantFinish(sum, v.quantStep[base][0]) : Rgb{};
  }
  const BrickRecord rec = live ? v.records[r] : BrickRecord{};
  const uint64_t mask = rec.mask();
  auto run = [&](const auto& read) {
    Rgb init;
    FootprintWeights fw;
    if (mask == 1u && !rec.raw()) init = read(uint64_t(rec.first()));  // only the average: no terms
    else if (mask) fw = footprintWeights(mask, rec.raw(), at.lx, at.ly, at.lz, at.fx, at.fy, at.fz);
    using Reader = std::decay_t<decltype(read)>;
    const Rgb sum = warpSum(init, fw, rec.maskLo, rec.maskHi, rec.first(), 0u, FloatValue<Reader>{read}, s);
    return live ? sum : Rgb{};
  };
  if (v.precision == Precision::Fp16) return run(CoefReader16{static_cast<const uint16_t*>(v.coefs) + 3 * off});
  return run(CoefReader32{static_cast<const float*>(v.coefs) + 3 * off});
}

}  // namespace canopy::haar
