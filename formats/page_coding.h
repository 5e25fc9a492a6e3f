// page_coding.h: the compressed pages of a 5.0 .canopy (canopy_layout.h, "5.0"): one Zstandard
// frame per page image, after a byte-plane filter. The writer (canopy_write.cpp) encodes, the
// reader (canopy_file.cpp) decodes; both through these functions.
#pragma once
#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

namespace canopy {

// The largest stored page of a page image of pageBytes (Zstandard's bound): a reader refuses more.
size_t canopyPageStoredBound(uint32_t pageBytes);

// Whether `filter` is one of the byte-plane filters (0: none; 2 or 4: the planes of 2- or 4-byte words).
inline bool canopyPageFilterValid(uint32_t filter) { return filter == 0 || filter == 2 || filter == 4; }

// Encodes a page image at Zstandard `level` into `stored` (replaced) with the filter (0, 2 or 4)
// whose frame is smallest at level 1 (the lowest on a tie); returns the filter. Deterministic.
// onlyFilter >= 0: that filter alone (tests).
uint32_t canopyPageEncode(const unsigned char* page, uint32_t pageBytes, int level, std::vector<unsigned char>& stored,
                          int onlyFilter = -1);

// Decodes a stored page into dst (pageBytes): "" or the problem (not one Zstandard frame of the
// current format, whose magic number it must begin with: libzstd's legacy decoders are never
// reached; not exactly pageBytes; an unknown filter). Never reads outside stored[0, storedBytes) or writes
// outside dst[0, pageBytes).
std::string canopyPageDecode(const unsigned char* stored, size_t storedBytes, uint32_t filter, unsigned char* dst, uint32_t pageBytes);

}  // namespace canopy
