// page_cache.cpp: see page_cache.h.
#include "runtime/page_cache.h"

#include <cstddef>

using std::size_t;

namespace canopy::play {

PageCache::PageCache(uint32_t pageCount, uint32_t slots)
    : table_(pageCount, -1), bad_(pageCount, 0), slotPage_(slots, -1), slotStamp_(slots, 0), prev_(slots, -1), next_(slots, -1) {
  free_.reserve(slots);
  for (uint32_t s = slots; s-- > 0;) free_.push_back(s);  // slot 0 first
}

void PageCache::unlink(uint32_t s) {
  const int32_t p = prev_[s], n = next_[s];
  if (p >= 0) next_[size_t(p)] = n; else head_ = n;
  if (n >= 0) prev_[size_t(n)] = p; else tail_ = p;
  prev_[s] = next_[s] = -1;
}

void PageCache::pushFront(uint32_t s) {
  prev_[s] = -1;
  next_[s] = head_;
  if (head_ >= 0) prev_[size_t(head_)] = int32_t(s);
  head_ = int32_t(s);
  if (tail_ < 0) tail_ = int32_t(s);
}

void PageCache::touch(uint32_t slot, uint32_t stamp) {
  if (slotPage_[slot] < 0) return;
  slotStamp_[slot] = stamp;
  unlink(slot);
  pushFront(slot);
}

PageCache::Assignment PageCache::assign(uint32_t page, uint32_t protectSince) {
  Assignment a;
  if (table_[page] >= 0) {
    a.slot = table_[page];
    return a;
  }
  uint32_t s;
  if (!free_.empty()) {
    s = free_.back();
    free_.pop_back();
  } else {
    if (tail_ < 0 || slotStamp_[size_t(tail_)] >= protectSince) return a;  // all in use this frame
    s = uint32_t(tail_);
    unlink(s);
    a.evicted = slotPage_[s];
    table_[size_t(a.evicted)] = -1;
    ++evictions_;
  }
  slotPage_[s] = page;
  slotStamp_[s] = protectSince;
  table_[page] = int32_t(s);
  pushFront(s);
  a.slot = int32_t(s);
  return a;
}

}  // namespace canopy::play
