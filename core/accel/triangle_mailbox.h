// TriangleMailbox: per-ray memory of the triangles already tested, so that a
// structure filing a triangle under several cells (the grids, the octree)
// tests it once per ray (mailboxing, Amanatides & Woo 1987). Small, direct
// mapped and on the stack: no per-triangle shared array to race on when
// threads trace the same brick, no allocation. A triangle evicted by another
// with the same slot is merely tested again, with the same answer. NoMailbox
// is the split-plane trees' choice (free: every test is done).
// CountingMailbox wraps one to count the tests it saved (benchmarks).
//
// Thread-safety: one per ray, on the tracing thread's stack.
#pragma once

#include <array>
#include <cstdint>

namespace outcore {

class TriangleMailbox {
 public:
  static constexpr uint32_t kSlots = 32;  // a power of two

  // True the first time `triangle` is seen (as far as the slots remember).
  bool first_visit(uint32_t triangle) {
    uint32_t& slot = slots_[triangle & (kSlots - 1)];
    if (slot == triangle) return false;
    slot = triangle;
    return true;
  }

 private:
  std::array<uint32_t, kSlots> slots_ = filled();
  static constexpr std::array<uint32_t, kSlots> filled() {
    std::array<uint32_t, kSlots> slots{};
    slots.fill(0xffffffffu);
    return slots;
  }
};

struct NoMailbox {
  static constexpr bool first_visit(uint32_t /*triangle*/) { return true; }
};

// Counts the references a walk reached and the tests the mailbox saved.
template <class Mailbox>
struct CountingMailbox {
  Mailbox mailbox;
  uint64_t references = 0;
  uint64_t saved = 0;
  bool first_visit(uint32_t triangle) {
    ++references;
    const bool first = mailbox.first_visit(triangle);
    saved += !first;
    return first;
  }
};

}  // namespace outcore
