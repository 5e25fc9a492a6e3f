// streaming.h: the loader thread and the per-frame cache update shared by both backends.
//
// After each render pass, endPass() reads the stamps the rays wrote: slots used this pass move to
// the front of the LRU list, and pages wanted this pass (missing, not bad, not already queued) are
// queued to the loader, as many as there are free staging buffers. Loader threads read pages with
// CanopyFile::readPage (pread + CRC check) into the staging buffers. beginPass() takes the finished
// reads, gives each page a slot (evicting the LRU page), enqueues the uploads and publishes the
// page table. A page that fails its check is reported once on stderr and marked bad: never cached,
// never asked for again; its bricks keep rendering from coarser data.
#pragma once
#include <condition_variable>
#include <cstdint>
#include <deque>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "formats/canopy_file.h"
#include "runtime/backend.h"
#include "runtime/page_cache.h"

namespace canopy::play {

struct StreamStats {
  uint64_t pagesUsed = 0;       // distinct pages sampled, summed over passes (hits)
  uint64_t pagesMissed = 0;     // distinct pages wanted but missing, summed over passes
  uint64_t pagesLoaded = 0;     // pages read, checked and uploaded
  uint64_t bytesLoaded = 0;     // their images' bytes
  uint64_t bytesRead = 0;       // the bytes read from the file for them (less with compressed pages)
  uint64_t pagesDeferred = 0;   // loads dropped because every slot was in use
  uint64_t corruptPages = 0;
  double loadSeconds = 0.0;     // summed time of the loader threads' reads
  uint64_t evictions = 0;
};

class Streamer {
 public:
  Streamer(const CanopyFile& file, Backend& backend, uint32_t slots, uint32_t stagingPages, int loaderThreads = 2);
  ~Streamer();
  Streamer(const Streamer&) = delete;
  Streamer& operator=(const Streamer&) = delete;

  // Before a render pass: installs finished loads and publishes the table. `frameStart` is the
  // stamp of the current frame's first pass (pages used since then are not evicted).
  void beginPass(uint32_t frameStart);
  // After the pass: LRU update and new requests. Returns the number of pages wanted this pass
  // that are missing and could still be loaded (0 = the pass was complete).
  uint32_t endPass(uint32_t stamp);
  // Blocks until every queued read has finished (converged rendering, tests).
  void waitLoader();
  bool idle();

  const StreamStats& stats() const { return stats_; }
  const PageCache& cache() const { return cache_; }

 private:
  struct Job {
    uint32_t page;
    uint32_t buffer;
    bool ok;
    std::string error;
    double seconds;
  };
  void loaderMain();
  void recycleStaging();

  const CanopyFile& file_;
  Backend& backend_;
  PageCache cache_;
  unsigned char* staging_;
  uint32_t pageBytes_;
  std::vector<uint32_t> freeBuffers_;
  std::vector<uint32_t> uploadedBuffers_;  // in flight on the backend until waitUploads()
  std::vector<uint8_t> queued_;            // page -> queued or being read
  std::vector<uint32_t> slotUsed_, pageWanted_;
  StreamStats stats_;

  std::mutex mutex_;
  std::condition_variable wake_, doneCv_;
  std::deque<Job> todo_, done_;
  uint32_t busy_ = 0;
  bool stop_ = false;
  std::vector<std::thread> threads_;
};

}  // namespace canopy::play
