# block_variant.py SRC OUT BLOCK TILESX MINBLOCKS: an edited copy of runtime/render_cuda.cu whose pixel kernel
# runs blocks of BLOCK threads on TILESX x (BLOCK/32/TILESX) warp tiles (one region of neighbouring tiles per
# block), with __launch_bounds__(BLOCK, MINBLOCKS), for bench/play/variant.sh (SRC=OUT). Measured: 320 threads
# (5 2 2) and 640 (5 4 1) were 1.00-1.13x slower than the default 128 on the real forest (docs/performance.md).
import sys
src, out, block, bx, minb = sys.argv[1], sys.argv[2], int(sys.argv[3]), int(sys.argv[4]), sys.argv[5]
s = open(src).read()
s = s.replace("constexpr int kPixelBlock = 128;", f"constexpr int kPixelBlock = {block};\nconstexpr int kBlockTilesX = {bx};", 1)
s = s.replace("__global__ void __launch_bounds__(kPixelBlock, kMinBlocks > 0 ? kMinBlocks : 1)\n    pixelKernel(",
              f"__global__ void __launch_bounds__(kPixelBlock, kMinBlocks > 0 ? {minb} : 1)\n    pixelKernel(", 1)
old = """  const int64_t i = blockIdx.x * int64_t(kPixelBlock) + threadIdx.x;
  if (i < n) k(i);
}"""
new = """  if (k.list) {
    const int64_t i = blockIdx.x * int64_t(kPixelBlock) + threadIdx.x;
    if (i < n) k(i);
    return;
  }
  constexpr int BX = kBlockTilesX, BY = (kPixelBlock / 32) / kBlockTilesX;
  const int tilesY = (k.y1 - k.y0 + k.tileH - 1) / k.tileH;
  const int blocksX = (k.tilesX + BX - 1) / BX;
  const int b = int(blockIdx.x), w = int(threadIdx.x) / 32, lane = int(threadIdx.x) % 32;
  const int tx = (b % blocksX) * BX + w % BX, ty = (b / blocksX) * BY + w / BX;
  if (tx >= k.tilesX || ty >= tilesY) return;
  k((int64_t(ty) * k.tilesX + tx) * (k.tileW * k.tileH) + lane);
}"""
assert old in s; s = s.replace(old, new, 1)
old = """  pixelKernel<kWithCones, kWithLight, kWithDepth, kBehind, kPaths, kMinBlocks><<<unsigned((n + kPixelBlock - 1) / kPixelBlock), kPixelBlock, 0, stream>>>(k, n);"""
new = """  int64_t blocks = (n + kPixelBlock - 1) / kPixelBlock;
  if (!k.list) {
    constexpr int BX = kBlockTilesX, BY = (kPixelBlock / 32) / kBlockTilesX;
    const int tilesY = (k.y1 - k.y0 + k.tileH - 1) / k.tileH;
    blocks = int64_t((k.tilesX + BX - 1) / BX) * ((tilesY + BY - 1) / BY);
  }
  pixelKernel<kWithCones, kWithLight, kWithDepth, kBehind, kPaths, kMinBlocks><<<unsigned(blocks), kPixelBlock, 0, stream>>>(k, n);"""
assert old in s; s = s.replace(old, new, 1)
open(out, 'w').write(s)
