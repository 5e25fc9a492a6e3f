// page_coding.cpp: see page_coding.h.
#include "formats/page_coding.h"

#include <zstd.h>

#include <cstring>
#include <memory>

namespace canopy {
namespace {

// The byte planes of a page's `width`-byte words (width 2 or 4; pageBytes is a multiple of 4):
// plane b holds byte b of every word. split: image -> planes; join: planes -> image.
void splitPlanes(const unsigned char* image, unsigned char* planes, uint32_t pageBytes, uint32_t width) {
  const uint32_t words = pageBytes / width;
  for (uint32_t b = 0; b < width; ++b)
    for (uint32_t i = 0; i < words; ++i) planes[size_t(b) * words + i] = image[size_t(i) * width + b];
}
void joinPlanes(const unsigned char* planes, unsigned char* image, uint32_t pageBytes, uint32_t width) {
  const uint32_t words = pageBytes / width;
  for (uint32_t b = 0; b < width; ++b)
    for (uint32_t i = 0; i < words; ++i) image[size_t(i) * width + b] = planes[size_t(b) * words + i];
}

struct CCtxFree {
  void operator()(ZSTD_CCtx* c) const { ZSTD_freeCCtx(c); }
};
struct DCtxFree {
  void operator()(ZSTD_DCtx* d) const { ZSTD_freeDCtx(d); }
};

}  // namespace

size_t canopyPageStoredBound(uint32_t pageBytes) { return ZSTD_compressBound(pageBytes); }

uint32_t canopyPageEncode(const unsigned char* page, uint32_t pageBytes, int level, std::vector<unsigned char>& stored, int onlyFilter) {
  thread_local std::unique_ptr<ZSTD_CCtx, CCtxFree> cctx(ZSTD_createCCtx());
  thread_local std::vector<unsigned char> planes, frame;
  stored.clear();
  if (!cctx) return 0;  // an empty `stored`: the writer reports it
  const size_t bound = ZSTD_compressBound(pageBytes);
  planes.resize(pageBytes);
  frame.resize(bound);
  // The filter is chosen at level 1, then the page is compressed at `level` with it (measured on a
  // lit detail plant at level 15: the file 0.8 % larger than with every filter tried at 15, packed in
  // 63 % of the time on 2 cores).
  const auto source = [&](uint32_t filter) {
    if (filter == 0) return page;
    splitPlanes(page, planes.data(), pageBytes, filter);
    return static_cast<const unsigned char*>(planes.data());
  };
  uint32_t best = onlyFilter >= 0 ? uint32_t(onlyFilter) : 0u;
  size_t smallest = 0;
  for (uint32_t filter : {0u, 2u, 4u}) {
    if (onlyFilter >= 0) break;  // forced: compressed once, below
    const size_t n = ZSTD_compressCCtx(cctx.get(), frame.data(), bound, source(filter), pageBytes, 1);
    if (ZSTD_isError(n)) continue;  // never for a valid level and a bound-sized buffer
    if (smallest == 0 || n < smallest) smallest = n, best = filter;
  }
  const size_t n = ZSTD_compressCCtx(cctx.get(), frame.data(), bound, source(best), pageBytes, level);
  if (!ZSTD_isError(n)) stored.assign(frame.data(), frame.data() + n);
  return best;
}

std::string canopyPageDecode(const unsigned char* stored, size_t storedBytes, uint32_t filter, unsigned char* dst, uint32_t pageBytes) {
  if (!canopyPageFilterValid(filter)) return "unknown page filter " + std::to_string(filter);
  // a frame of today's format only (a hostile file must not reach the legacy formats' decoders)
  uint32_t magic = 0;
  if (storedBytes >= 4) std::memcpy(&magic, stored, 4);
  if (magic != ZSTD_MAGICNUMBER) return "stored page is not a Zstandard frame (magic number)";
  thread_local std::unique_ptr<ZSTD_DCtx, DCtxFree> dctx(ZSTD_createDCtx());
  if (!dctx) return "out of memory for a Zstandard decoder";
  thread_local std::vector<unsigned char> planes;
  unsigned char* out = dst;
  if (filter != 0) {
    planes.resize(pageBytes);
    out = planes.data();
  }
  // the frame must hold exactly one page image: its declared size, then what it decodes to
  const unsigned long long declared = ZSTD_getFrameContentSize(stored, storedBytes);
  if (declared != pageBytes) return "stored page is not one Zstandard frame of " + std::to_string(pageBytes) + " bytes";
  if (ZSTD_findFrameCompressedSize(stored, storedBytes) != storedBytes) return "stored page has bytes after its Zstandard frame";
  const size_t n = ZSTD_decompressDCtx(dctx.get(), out, pageBytes, stored, storedBytes);
  if (ZSTD_isError(n)) return std::string("stored page does not decompress (") + ZSTD_getErrorName(n) + ")";
  if (n != pageBytes) return "stored page decompresses to " + std::to_string(n) + " bytes, not " + std::to_string(pageBytes);
  if (filter != 0) joinPlanes(planes.data(), dst, pageBytes, filter);
  return "";
}

}  // namespace canopy
