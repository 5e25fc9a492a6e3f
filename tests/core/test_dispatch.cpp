// The dispatch layer runs one CANOPY_HD functor on TBB and, where a GPU exists, as a CUDA kernel.
#include <gtest/gtest.h>

#include <atomic>
#include <cmath>
#include <cstring>

#include "canopy/device.h"
#include "canopy/half.h"
#include "canopy/parallel.h"
#include "saxpy.h"

namespace {
std::vector<float> ramp(size_t n, float scale) {
  std::vector<float> v(n);
  for (size_t i = 0; i < n; ++i) v[i] = scale * float(i % 1000) - 3.0f;
  return v;
}
}  // namespace

TEST(Dispatch, CpuParallelForVisitsEveryIndexOnce) {
  const int64_t n = 1'000'003;
  std::vector<std::atomic<int>> hits(n);
  canopy::parallelFor(n, [&](int64_t i) { hits[i]++; });
  for (int64_t i = 0; i < n; ++i) ASSERT_EQ(hits[i].load(), 1) << i;
}

TEST(Dispatch, CpuSaxpyMatchesSerial) {
  const size_t n = 100'000;
  auto x = ramp(n, 0.5f), y = ramp(n, -0.25f), ref = y;
  canopy::parallelFor(int64_t(n), Saxpy{2.5f, x.data(), y.data()});
  canopy::serialFor(int64_t(n), Saxpy{2.5f, x.data(), ref.data()});
  EXPECT_EQ(y, ref);
}

TEST(Dispatch, cuda_SaxpyMatchesCpu) {
  if (canopy::cudaDeviceCount() == 0) GTEST_SKIP() << "no CUDA GPU";
#ifdef CANOPY_HAS_CUDA
  const size_t n = 1'000'000;
  auto x = ramp(n, 0.5f), y = ramp(n, -0.25f), ref = y;
  saxpyCuda(2.5f, x, y);
  canopy::serialFor(int64_t(n), Saxpy{2.5f, x.data(), ref.data()});
  // Inputs are small multiples of 1/4, so a*x+y is exact in fp32 with or without FMA contraction:
  // the GPU must agree bit for bit.
  EXPECT_EQ(y, ref);
#endif
}

TEST(Dispatch, cuda_HalfToFloatMatchesCpuForEveryHalf) {
  if (canopy::cudaDeviceCount() == 0) GTEST_SKIP() << "no CUDA GPU";
#ifdef CANOPY_HAS_CUDA
  // The device converts with the hardware instruction (NaN/Inf excepted), the host in software:
  // the same bits for all 65536 inputs, NaN payloads included.
  const std::vector<uint32_t> gpu = halfToFloatAllCuda();
  for (uint32_t h = 0; h < 65536; ++h) {
    const float f = canopy::halfToFloat(uint16_t(h));
    uint32_t cpu;
    std::memcpy(&cpu, &f, sizeof cpu);
    ASSERT_EQ(gpu[h], cpu) << "half 0x" << std::hex << h;
  }
  // halfValue: the bare hardware conversion; the same bits but for NaN's payload.
  const std::vector<uint32_t> value = halfToFloatAllCuda(true);
  for (uint32_t h = 0; h < 65536; ++h) {
    const float f = canopy::halfToFloat(uint16_t(h));
    uint32_t cpu;
    std::memcpy(&cpu, &f, sizeof cpu);
    if (std::isnan(f))
      ASSERT_EQ(value[h] & 0x7f800000u, 0x7f800000u) << "half 0x" << std::hex << h;
    else
      ASSERT_EQ(value[h], cpu) << "half 0x" << std::hex << h;
    ASSERT_EQ(std::isnan(f), (value[h] & 0x7fffffffu) > 0x7f800000u) << "half 0x" << std::hex << h;
  }
#endif
}
