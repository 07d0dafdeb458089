// What every native header shares: the constants the Python side generates (the preamble
// warptex.kernels.native writes before the headers: WT_L, the address and filter modes...) and the
// inline attribute. Compiled on the CPU only (the lane kernels are CPU-only; on CUDA the native
// functions' bodies are their #else branches).
#pragma once
#ifndef WT_CONSTANTS
#error "wt_config.h: the constants come first: include the headers through warptex.kernels.native's preamble"
#endif

#define WT_INLINE static inline __attribute__((always_inline))
// A function compiled once, out of line, that many inlined callers share.
#define WT_OUTLINE static __attribute__((noinline))
