// item_pages.h: whole variable-size items packed greedily into page payloads, the layout of Haar
// light pages and sparse brick pages (canopy_layout.h): payload = uint32 offset[n + 1] (offset[0] =
// 4 (n + 1), offset[n] = payload bytes), then the n items; at most maxItems items per page.
#pragma once
#include <cstdint>
#include <cstring>
#include <utility>
#include <vector>

#include "formats/canopy_layout.h"

namespace canopy {

class CanopyItemPager {
 public:
  CanopyItemPager(uint32_t pageBytes, uint32_t maxItems) : capacity_(pageBytes - uint32_t(sizeof(CanopyPageHeader))), maxItems_(maxItems) {}

  // Appends an item (a multiple of 4 bytes long); returns its page (counted from 0) and its index
  // in that page.
  std::pair<uint32_t, uint32_t> add(std::vector<unsigned char> item) {
    if (!pending_.empty() && (pending_.size() == maxItems_ || 4 * (pending_.size() + 2) + pendingBytes_ + item.size() > capacity_))
      flush();
    const std::pair<uint32_t, uint32_t> at{uint32_t(payloads.size()), uint32_t(pending_.size())};
    pendingBytes_ += item.size();
    pending_.push_back(std::move(item));
    return at;
  }
  // Closes the last page.
  void finish() { flush(); }

  std::vector<std::vector<unsigned char>> payloads;  // one per page
  std::vector<uint32_t> itemCounts;                  // items per page

 private:
  void flush() {
    if (pending_.empty()) return;
    const uint32_t n = uint32_t(pending_.size());
    std::vector<unsigned char> payload(4 * (size_t(n) + 1));
    uint32_t at = uint32_t(payload.size());
    for (uint32_t i = 0; i <= n; ++i) {
      std::memcpy(payload.data() + 4 * i, &at, 4);
      if (i < n) at += uint32_t(pending_[i].size());
    }
    for (const auto& item : pending_) payload.insert(payload.end(), item.begin(), item.end());
    payloads.push_back(std::move(payload));
    itemCounts.push_back(n);
    pending_.clear();
    pendingBytes_ = 0;
  }

  uint32_t capacity_, maxItems_;
  std::vector<std::vector<unsigned char>> pending_;
  uint64_t pendingBytes_ = 0;
};

}  // namespace canopy
