// hd.h: the one macro that marks per-element code shared by the CPU and CUDA backends.
//
// Functions that hold the physics and the codecs (one LB node update, one Haar brick lift, one
// cone step) are written once, marked CANOPY_HD, and compiled for both the host (TBB, tests) and
// the device (CUDA kernels). Under a plain C++ compiler the macro is empty.
#pragma once

#if defined(__CUDACC__)
#define CANOPY_HD __host__ __device__
#define CANOPY_FORCEINLINE __forceinline__
#else
#define CANOPY_HD
#define CANOPY_FORCEINLINE inline
#endif

// CANOPY_UNROLL: in device code, fully unroll the next fixed-trip loop (the 19 LB directions, a Haar
// brick's 4 coefficients per axis), so that constants fold and small per-element arrays stay in
// registers (dissertation listing 5.2). Host compilers are left to decide: GCC vectorises these
// loops better when they stay rolled.
#if defined(__CUDA_ARCH__)
#define CANOPY_UNROLL _Pragma("unroll")
#else
#define CANOPY_UNROLL
#endif
