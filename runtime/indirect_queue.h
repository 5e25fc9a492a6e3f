// indirect_queue.h: a primary cone's shading segments queued for their indirect light, so that a
// warp evaluates it with all its lanes busy. Part of runtime/cone.h.
//
// The megakernel's problem (docs/performance.md, "Queued indirect light"): a lane finds a shading
// segment at some steps and not at others, so the indirect light of a step (the scene factors and
// the LB light: 40 loads and some 600 instructions per segment) ran with the 13-16 lanes of 32 that
// had one. Its value is only ever added to the pixel: the march needs the segment's extinction,
// never its light. So the march queues the segment instead (its light item, node-local point, ray
// parameter, instance, and weight k x albedo), and once the warp holds a round of them, every lane
// takes one of any lane's entries, evaluates it (itemIndirect, the same code as the inline path) and
// hands the product back to the entry's lane, which adds its entries in the order it found them.
//
// The pixel gets the same terms, summed in another order: the inline path adds
// scale x (k albedo direct Tsun + sum over the step's segments of k albedo x indirect) per step
// (shadeStep); the queue adds the direct part per step and (k albedo x scale) x indirect per segment,
// in a second sum that joins the first when the ray ends. The difference is float rounding.
//
// Lanes: the policy of the lanes that share a queue: WarpLanes (cone.h, CUDA: a warp's 32 lanes,
// with its ballot, shuffles and sync) or OneLane (the CPU's tests of the queue's bookkeeping: a
// queue of one lane, rounds of kBatch entries, so that rounds leave entries behind and entries
// fall back to the inline path as on the GPU).
#pragma once
#include "runtime/shadow_map.h"

namespace canopy::play {

CANOPY_HD CANOPY_FORCEINLINE uint32_t popCount(uint32_t m) {
#if defined(__CUDA_ARCH__)
  return uint32_t(__popc(m));
#else
  return uint32_t(__builtin_popcount(m));
#endif
}

// No queue: every segment's indirect light is evaluated where it is found (the CPU reference, the
// stereo and shadow-cone kernels).
struct InlineIndirect {
  static constexpr bool kQueues = false;
};

// A queue's entries, kLanes x kSlots, slot-major (lane fastest: a step's pushes of the warp's lanes
// fall in different banks), and the order of one round's entries.
template <int kLanes, int kSlots>
struct IndirectQueueStorage {
  const uint32_t* item[kSlots][kLanes];  // the light item (nullptr: the density-only term)
  float l[3][kSlots][kLanes];            // node-local coordinates in the light item
  float t[kSlots][kLanes];               // the ray parameter of the sample (the scene factors' point o + d t)
  uint32_t instance[kSlots][kLanes];     // its sun weights
  float w[3][kSlots][kLanes];            // k x albedo, then x the step's scale; after a round: x indirect
  uint16_t order[kSlots * kLanes];       // a round's entries: slot x kLanes + lane
};

// The one lane of a CPU queue.
struct OneLane {
  static constexpr int kLanes = 1;
  CANOPY_HD static uint32_t lane() { return 0; }
  CANOPY_HD static uint32_t lanesBelow() { return 0; }
  CANOPY_HD static bool any(bool b) { return b; }
  CANOPY_HD static uint32_t ballot(bool b) { return b ? 1u : 0u; }
  CANOPY_HD static uint32_t sum(uint32_t v) { return v; }
  CANOPY_HD static float shuffle(float v, uint32_t) { return v; }
  CANOPY_HD static void sync() {}
};

// A lane's view of its queue: its entries are a ring of kSlots in its column of the storage (head,
// count), the last `pushed` of them found in the current step. kBatch: a round's size (a multiple
// of kLanes; the warp's width on the GPU).
template <class Lanes, int kSlots, int kBatch = Lanes::kLanes>
struct IndirectQueue {
  static constexpr bool kQueues = true;
  static constexpr int kLanes = Lanes::kLanes;
  static_assert((kSlots & (kSlots - 1)) == 0 && kSlots * kLanes <= 65536, "a ring of a power of two; orders in 16 bits");
  static_assert(kBatch % kLanes == 0, "rounds of whole lanes");
  using Storage = IndirectQueueStorage<kLanes, kSlots>;
  Storage* q;
  uint32_t head = 0, count = 0, pushed = 0;
  float rgb[3] = {0.0f, 0.0f, 0.0f};  // the indirect light of the lane's evaluated entries, summed in their order

  // Whether any lane sharing the queue is `alive`.
  CANOPY_HD CANOPY_FORCEINLINE bool any(bool alive) const { return Lanes::any(alive); }
  CANOPY_HD CANOPY_FORCEINLINE uint32_t slot(uint32_t age) const { return (head + age) & uint32_t(kSlots - 1); }

  // Queues shading segment g of `instance` with weight ka = k x albedo; false where the ring is full
  // (the caller then evaluates it inline).
  CANOPY_HD CANOPY_FORCEINLINE bool push(const Segment& g, uint32_t instance, const float ka[3]) {
    if (count == uint32_t(kSlots)) return false;
    const uint32_t s = slot(count), lane = Lanes::lane();
    q->item[s][lane] = g.lightItem;
    for (int a = 0; a < 3; ++a) q->l[a][s][lane] = g.light[a];
    q->t[s][lane] = g.tSample;
    q->instance[s][lane] = instance;
    for (int c = 0; c < 3; ++c) q->w[c][s][lane] = ka[c];
    ++count, ++pushed;
    return true;
  }

  // The step that queued the last `pushed` entries is shaded with `scale` (shadeStep: T alpha / k),
  // or not at all (scale 0: its entries are dropped, as the inline path adds nothing for it).
  CANOPY_HD CANOPY_FORCEINLINE void endStep(float scale) {
    if (!(scale > 0.0f)) {
      count -= pushed;
    } else {
      const uint32_t lane = Lanes::lane();
      for (uint32_t k = count - pushed; k < count; ++k)
        for (int c = 0; c < 3; ++c) q->w[c][slot(k)][lane] *= scale;
    }
    pushed = 0;
  }

  // All lanes, between steps: evaluates the queued entries once there is a round of them (or a
  // lane's ring is nearly full, or `last`: the lanes' rays have all ended). A round takes the
  // oldest entries first, every lane's oldest before any lane's second, so each lane's evaluated
  // entries are the oldest of its ring and it adds them in the order it found them.
  template <bool kWithLight>
  CANOPY_HD CANOPY_FORCEINLINE void serve(const SceneView& s, V3 o, V3 d, bool last) {
    const uint32_t total = Lanes::sum(count);
    const bool crowded = Lanes::any(count + 2u > uint32_t(kSlots));  // a step finding two segments might not fit
    if (total == 0 || !(last || crowded || total >= uint32_t(kBatch))) return;
    const uint32_t n = last || total < uint32_t(kBatch) ? total : total - total % uint32_t(kBatch);
    const uint32_t lane = Lanes::lane(), below = Lanes::lanesBelow();
    uint32_t base = 0, taken = 0;
    for (int age = 0; age < kSlots; ++age) {
      const uint32_t holds = Lanes::ballot(uint32_t(age) < count);
      const uint32_t at = base + popCount(holds & below);
      if (uint32_t(age) < count && at < n) q->order[at] = uint16_t(slot(uint32_t(age)) * uint32_t(kLanes) + lane), ++taken;
      base += popCount(holds);
    }
    Lanes::sync();
    for (uint32_t r = 0; r < n; r += uint32_t(kLanes)) {
      const uint32_t j = r + lane;
      const uint32_t e = j < n ? q->order[j] : lane;
      const uint32_t es = e / uint32_t(kLanes), owner = e % uint32_t(kLanes);
      const V3 eo = v3(Lanes::shuffle(o.x, owner), Lanes::shuffle(o.y, owner), Lanes::shuffle(o.z, owner));
      const V3 ed = v3(Lanes::shuffle(d.x, owner), Lanes::shuffle(d.y, owner), Lanes::shuffle(d.z, owner));
      if (j < n) {
        const float l[3] = {q->l[0][es][owner], q->l[1][es][owner], q->l[2][es][owner]};
        float ind[3];
        itemIndirect<kWithLight>(s, s.instances[q->instance[es][owner]].sunWeights, q->item[es][owner], l, eo + ed * q->t[es][owner], ind);
        for (int c = 0; c < 3; ++c) q->w[c][es][owner] *= ind[c];
      }
    }
    Lanes::sync();
    for (uint32_t age = 0; age < taken; ++age)
      for (int c = 0; c < 3; ++c) rgb[c] += q->w[c][slot(age)][lane];
    head = slot(taken);
    count -= taken;
    Lanes::sync();  // the slots and the order are written again after this
  }
};

}  // namespace canopy::play
