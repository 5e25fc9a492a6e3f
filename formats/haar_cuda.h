// haar_cuda.h: a .chaar on the GPU (CUDA builds only: link canopy_chaar_cuda).
//
// ChaarDevice uploads a validated ChaarData once; view() returns the same POD ChaarView the CPU
// uses, holding device pointers, so a player kernel can call chaarSample(view, base, x, y, z) from
// its own code (include formats/haar_view.h in the .cu). The sampler is one thread per sample: it
// reads the brick's 12-byte record, finds each needed coefficient with the mask and a popcount
// (listing 5.5's rule, without the shared-memory staging, barriers or 64-thread cooperation) and
// reconstructs only the 2^3 texels of its footprint. sample() and decodeDense() are the batch
// entry points used by tests and benchmarks. No CUDA headers here: host code can include it.
#pragma once
#include <cstddef>
#include <cstdint>
#include <vector>

#include "formats/chaar.h"

namespace canopy::haar {

class ChaarDevice {
 public:
  // Uploads to the current CUDA device. Throws canopy::Error(Runtime) on CUDA errors.
  explicit ChaarDevice(const ChaarData& data);
  ~ChaarDevice();
  ChaarDevice(const ChaarDevice&) = delete;
  ChaarDevice& operator=(const ChaarDevice&) = delete;

  const ChaarView& view() const { return view_; }  // device pointers
  size_t deviceBytes() const { return bytes_; }

  // Trilinear samples of `base` at n index-space points (xyz triples, host memory) -> rgb triples.
  void sample(uint32_t base, const float* pointsHost, size_t n, float* rgbHost) const;
  // Same with device pointers (no copies): for benchmarks. `stream` is a cudaStream_t.
  void sampleDevice(uint32_t base, const float* pointsDev, size_t n, float* rgbDev, void* stream = nullptr) const;
  // Every lattice cell decoded from its owning brick on the GPU (layout of decodeBaseDense).
  void decodeDense(uint32_t base, std::vector<float>& out) const;

 private:
  ChaarView view_;
  uint32_t* slots_ = nullptr;
  BrickRecord* records_ = nullptr;
  QuantRecord* quantRecords_ = nullptr;
  void* coefs_ = nullptr;
  size_t bytes_ = 0;
};

}  // namespace canopy::haar
