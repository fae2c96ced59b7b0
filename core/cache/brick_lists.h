// BrickLists<K>: K doubly linked lists of brick ids sharing one set of link
// arrays indexed by brick id (ids are dense), each brick in at most one list.
// The building block of the queue-based policies (clock, arc, s3fifo): push,
// remove and move are O(1) with no allocation once the arrays have grown to
// the largest id. "Front" is the newest end, "back" the oldest.
//
// Thread-safety: none (owned by one policy, used under the cache's lock).
#pragma once

#include <array>
#include <cassert>
#include <cstdint>
#include <vector>

namespace outcore {

template <int K>
class BrickLists {
 public:
  static constexpr uint32_t kNone = 0xffffffffu;
  static constexpr uint8_t kNoList = 0xff;

  // Which list holds `brick`, or kNoList.
  uint8_t list_of(uint32_t brick) const { return brick < list_.size() ? list_[brick] : kNoList; }
  bool contains(uint32_t brick) const { return list_of(brick) != kNoList; }

  void push_front(int list, uint32_t brick) {
    assert(list >= 0 && list < K && brick != kNone && !contains(brick));
    if (brick >= list_.size()) {
      toward_front_.resize(brick + 1, kNone);
      toward_back_.resize(brick + 1, kNone);
      list_.resize(brick + 1, kNoList);
    }
    toward_front_[brick] = kNone;
    toward_back_[brick] = front_[list];
    if (front_[list] != kNone) toward_front_[front_[list]] = brick;
    front_[list] = brick;
    if (back_[list] == kNone) back_[list] = brick;
    list_[brick] = static_cast<uint8_t>(list);
    ++size_[list];
  }

  void remove(uint32_t brick) {
    assert(contains(brick));
    const int list = list_[brick];
    const uint32_t newer = toward_front_[brick];
    const uint32_t older = toward_back_[brick];
    if (newer != kNone)
      toward_back_[newer] = older;
    else
      front_[list] = older;
    if (older != kNone)
      toward_front_[older] = newer;
    else
      back_[list] = newer;
    toward_front_[brick] = toward_back_[brick] = kNone;
    list_[brick] = kNoList;
    --size_[list];
  }

  // Moves `brick` (in any list) to the front of `list`.
  void move_to_front(int list, uint32_t brick) {
    if (contains(brick)) remove(brick);
    push_front(list, brick);
  }

  uint32_t front(int list) const { return front_[list]; }
  uint32_t back(int list) const { return back_[list]; }
  // The next newer brick of the same list, or kNone at the front.
  uint32_t newer(uint32_t brick) const { return toward_front_[brick]; }
  uint32_t size(int list) const { return size_[list]; }

  // One list, oldest first (for tests and reports).
  std::vector<uint32_t> oldest_first(int list) const {
    std::vector<uint32_t> out;
    out.reserve(size_[list]);
    for (uint32_t b = back_[list]; b != kNone; b = toward_front_[b]) out.push_back(b);
    return out;
  }

 private:
  std::vector<uint32_t> toward_front_;
  std::vector<uint32_t> toward_back_;
  std::vector<uint8_t> list_;
  std::array<uint32_t, K> front_ = filled(kNone);
  std::array<uint32_t, K> back_ = filled(kNone);
  std::array<uint32_t, K> size_ = filled(0);

  static constexpr std::array<uint32_t, K> filled(uint32_t value) {
    std::array<uint32_t, K> a{};
    for (auto& x : a) x = value;
    return a;
  }
};

}  // namespace outcore
