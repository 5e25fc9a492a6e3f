// streaming.cpp: see streaming.h.
#include "runtime/streaming.h"

#include <chrono>

#include "canopy/cli.h"
#include "canopy/errors.h"

namespace canopy::play {

Streamer::Streamer(const CanopyFile& file, Backend& backend, uint32_t slots, uint32_t stagingPages, int loaderThreads)
    : file_(file),
      backend_(backend),
      cache_(file.pageCount(), slots),
      staging_(nullptr),
      pageBytes_(file.header().pageBytes),
      queued_(file.pageCount(), 0),
      slotUsed_(slots, 0),
      pageWanted_(file.pageCount(), 0) {
  if (stagingPages == 0) stagingPages = 1;
  staging_ = backend_.stagingBuffers(stagingPages);
  for (uint32_t b = stagingPages; b-- > 0;) freeBuffers_.push_back(b);
  for (int t = 0; t < loaderThreads; ++t) threads_.emplace_back([this] { loaderMain(); });
}

Streamer::~Streamer() {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    stop_ = true;
  }
  wake_.notify_all();
  for (auto& t : threads_) t.join();
}

void Streamer::loaderMain() {
  std::unique_lock<std::mutex> lock(mutex_);
  for (;;) {
    wake_.wait(lock, [this] { return stop_ || !todo_.empty(); });
    if (stop_) return;
    Job job = todo_.front();
    todo_.pop_front();
    ++busy_;
    lock.unlock();
    const auto t0 = std::chrono::steady_clock::now();
    try {
      unsigned char* page = staging_ + size_t(job.buffer) * pageBytes_;
      file_.readPage(job.page, page);
      canopyPreparePage(page, file_.header());  // brick masks for the empty-cell skip; light items of files before 4.0
      job.ok = true;
    } catch (const std::exception& e) {
      job.ok = false;
      job.error = e.what();
    }
    job.seconds = secondsSince(t0);
    lock.lock();
    --busy_;
    done_.push_back(std::move(job));
    doneCv_.notify_all();
  }
}

void Streamer::waitLoader() {
  std::unique_lock<std::mutex> lock(mutex_);
  doneCv_.wait(lock, [this] { return todo_.empty() && busy_ == 0; });
}

bool Streamer::idle() {
  std::lock_guard<std::mutex> lock(mutex_);
  return todo_.empty() && busy_ == 0 && done_.empty();
}

void Streamer::recycleStaging() {
  // staging buffers of earlier uploads are free once the copies completed
  if (!uploadedBuffers_.empty()) {
    backend_.waitUploads();
    freeBuffers_.insert(freeBuffers_.end(), uploadedBuffers_.begin(), uploadedBuffers_.end());
    uploadedBuffers_.clear();
  }
}

void Streamer::beginPass(uint32_t frameStart) {
  recycleStaging();
  std::deque<Job> finished;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    finished.swap(done_);
  }
  bool changed = false;
  for (Job& j : finished) {
    queued_[j.page] = 0;
    stats_.loadSeconds += j.seconds;
    if (!j.ok) {
      cache_.markBad(j.page);
      ++stats_.corruptPages;
      logWarn(j.error + " (page " + std::to_string(j.page) +
              " is not cached; its bricks render from coarser data)");
      freeBuffers_.push_back(j.buffer);
      continue;
    }
    const PageCache::Assignment a = cache_.assign(j.page, frameStart);
    if (a.slot < 0) {
      ++stats_.pagesDeferred;
      freeBuffers_.push_back(j.buffer);
      continue;
    }
    backend_.upload(uint32_t(a.slot), staging_ + size_t(j.buffer) * pageBytes_);
    uploadedBuffers_.push_back(j.buffer);
    ++stats_.pagesLoaded;
    stats_.bytesLoaded += pageBytes_;
    stats_.bytesRead += file_.storedBytes(j.page);
    changed = true;
  }
  if (changed) backend_.setPageTable(cache_.table());
  stats_.evictions = cache_.evictions();
}

uint32_t Streamer::endPass(uint32_t stamp) {
  // this pass's kernel waited for the uploads of its beginPass (the page table is published after
  // them), so their staging buffers are free now at no cost; without this a pass that installed a
  // full batch could queue nothing, and a converging frame would stop after two batches
  recycleStaging();
  backend_.readStamps(slotUsed_, pageWanted_);
  for (uint32_t s = 0; s < slotUsed_.size(); ++s)
    if (slotUsed_[s] == stamp) {
      cache_.touch(s, stamp);
      ++stats_.pagesUsed;
    }
  uint32_t pending = 0;
  std::vector<Job> jobs;
  for (uint32_t p = 0; p < pageWanted_.size(); ++p) {
    if (pageWanted_[p] != stamp) continue;
    ++stats_.pagesMissed;
    if (cache_.bad(p) || cache_.resident(p)) continue;
    ++pending;
    if (queued_[p] || freeBuffers_.empty()) continue;
    queued_[p] = 1;
    jobs.push_back(Job{p, freeBuffers_.back(), false, {}, 0.0});
    freeBuffers_.pop_back();
  }
  if (!jobs.empty()) {
    {
      std::lock_guard<std::mutex> lock(mutex_);
      for (auto& j : jobs) todo_.push_back(std::move(j));
    }
    wake_.notify_all();
  }
  return pending;
}

}  // namespace canopy::play
