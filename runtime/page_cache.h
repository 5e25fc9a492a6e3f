// page_cache.h: the host-side bookkeeping of the brick page cache (GigaVoxels ch. 7, digest §4).
//
// `slots` pool slots hold pages; table()[page] is the slot or -1. LRU order is an intrusive list
// over slots: touch() moves a slot used in the current frame to the front; assign() takes a free
// slot or evicts the tail (least recently used), but never a slot used in the current frame, all
// of whose passes count (then the load is deferred: the page stays missing and is asked for again
// by a later frame). A page
// found corrupt is marked bad and never cached or requested again.
#pragma once
#include <cstdint>
#include <vector>

namespace canopy::play {

class PageCache {
 public:
  PageCache(uint32_t pageCount, uint32_t slots);

  uint32_t slots() const { return uint32_t(slotPage_.size()); }
  const std::vector<int32_t>& table() const { return table_; }
  bool resident(uint32_t page) const { return table_[page] >= 0; }
  bool bad(uint32_t page) const { return bad_[page] != 0; }
  void markBad(uint32_t page) { bad_[page] = 1; }

  // Marks slot used in frame `stamp` (most recently used).
  void touch(uint32_t slot, uint32_t stamp);
  struct Assignment {
    int32_t slot = -1;       // -1: deferred (every slot in use this frame)
    int64_t evicted = -1;    // the page that lost the slot, or -1
  };
  // Gives `page` a slot (free or LRU) and updates the table. Slots used at or after stamp
  // `protectSince` (the current frame's first pass) are never evicted; the new page counts as used
  // at protectSince (it was asked for by this frame or the one before).
  Assignment assign(uint32_t page, uint32_t protectSince);
  uint64_t evictions() const { return evictions_; }

 private:
  void unlink(uint32_t slot);
  void pushFront(uint32_t slot);

  std::vector<int32_t> table_;       // page -> slot
  std::vector<uint8_t> bad_;
  std::vector<int64_t> slotPage_;    // slot -> page or -1
  std::vector<uint32_t> slotStamp_;  // slot -> last frame used
  std::vector<int32_t> prev_, next_; // LRU list (front = most recent)
  int32_t head_ = -1, tail_ = -1;
  std::vector<uint32_t> free_;
  uint64_t evictions_ = 0;
};

}  // namespace canopy::play
