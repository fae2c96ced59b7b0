// What the CPU running us can do beyond the build's baseline (x86-64-v2), for
// code that picks an AVX path at run time (the upper traversals).
//
// Thread-safety: the answer is computed once, on first use, thread-safely.
#pragma once

namespace outcore {

// True when this CPU (and OS) run AVX code.
inline bool cpu_has_avx() {
#if defined(__x86_64__) || defined(__i386__)
  static const bool available = __builtin_cpu_supports("avx");
  return available;
#else
  return false;
#endif
}

}  // namespace outcore
