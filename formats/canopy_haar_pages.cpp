// canopy_haar_pages.cpp: a .chaar's bricks re-paged as the Haar light of a .canopy model
// (canopy_write.h, layout in canopy_layout.h "Haar light pages").
#include <cstring>

#include "canopy/errors.h"
#include "formats/canopy_write.h"
#include "formats/chaar.h"
#include "formats/item_pages.h"

namespace canopy {

CanopyHaarPages canopyHaarPagesFromChaar(const haar::ChaarData& d, uint32_t pageBytes) {
  const haar::ChaarHeader& h = d.header;
  if (h.baseCount != kCanopyLightBases)
    throw invalidInput("canopy writer: a .chaar with " + std::to_string(h.baseCount) + " bases; Haar light needs " +
                       std::to_string(kCanopyLightBases));
  if (d.precision() == haar::Precision::Quant)
    throw unsupported("canopy writer: quantised Haar light (.chaar 2.x) has no Haar page layout yet");
  CanopyHaarPages out;
  out.precision = h.precision;
  out.threshold = h.threshold;
  const bool fp16 = d.precision() == haar::Precision::Fp16;
  const size_t entryBytes = fp16 ? 6 : 12;
  const uint32_t E = kCanopyHaarGroupEdge;
  uint64_t groups = 1;
  for (int a = 0; a < 3; ++a) {
    out.brickDims[a] = h.brickDims[a];
    out.groupDims[a] = (uint32_t(h.brickDims[a]) + E - 1) / E;
    groups *= out.groupDims[a];
  }
  out.index.assign(size_t(groups), kCanopyNone);
  CanopyItemPager pager(pageBytes, kCanopyHaarMaxItemsPerPage);  // items in whole-item pages

  const int32_t* bd = h.brickDims;
  for (uint32_t gz = 0; gz < out.groupDims[2]; ++gz)
    for (uint32_t gy = 0; gy < out.groupDims[1]; ++gy)
      for (uint32_t gx = 0; gx < out.groupDims[0]; ++gx) {
        uint32_t block = kCanopyNone;
        for (uint32_t local = 0; local < kCanopyHaarGroupBricks; ++local) {
          const uint32_t b[3] = {gx * E + local % E, gy * E + (local / E) % E, gz * E + local / (E * E)};
          if (b[0] >= uint32_t(bd[0]) || b[1] >= uint32_t(bd[1]) || b[2] >= uint32_t(bd[2])) continue;
          const uint32_t slot = d.slots[(size_t(b[2]) * uint32_t(bd[1]) + b[1]) * uint32_t(bd[0]) + b[0]];
          if (slot == haar::kEmptySlot) continue;
          if (block == kCanopyNone) {
            block = out.groups++;
            out.index[(size_t(gz) * out.groupDims[1] + gy) * out.groupDims[0] + gx] = block;
            out.index.resize(out.index.size() + kCanopyHaarGroupBricks, kCanopyNone);
          }
          // The item: 19 records rebased on the item's own coefficients, then those coefficients.
          haar::BrickRecord recs[kCanopyLightBases];
          std::vector<unsigned char> coefs;
          uint32_t entries = 0;
          for (uint32_t base = 0; base < kCanopyLightBases; ++base) {
            const haar::BrickRecord& r = d.records[size_t(base) * h.slotCount + slot];
            const uint32_t n = uint32_t(haar::popcount64(r.mask()));
            recs[base].set(r.mask(), entries, r.raw());
            const uint64_t src = d.bases[base].coefOffset + r.first();
            const unsigned char* from = fp16 ? reinterpret_cast<const unsigned char*>(d.coefs16.data() + 3 * src)
                                             : reinterpret_cast<const unsigned char*>(d.coefs32.data() + 3 * src);
            coefs.insert(coefs.end(), from, from + n * entryBytes);
            entries += n;
          }
          std::vector<unsigned char> item(kCanopyHaarRecordBytes);
          std::memcpy(item.data(), recs, kCanopyHaarRecordBytes);
          item.insert(item.end(), coefs.begin(), coefs.end());
          item.resize((item.size() + 3) / 4 * 4, 0);
          const auto [page, inPage] = pager.add(std::move(item));
          out.index[size_t(groups) + size_t(block) * kCanopyHaarGroupBricks + local] = (page << kCanopyHaarItemBits) | inPage;
          ++out.items;
        }
      }
  pager.finish();
  out.payloads = std::move(pager.payloads);
  out.itemCounts = std::move(pager.itemCounts);
  return out;
}

}  // namespace canopy
