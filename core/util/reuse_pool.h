// ReusePool<T>: a few spare objects kept for the next taker, so that warm
// calls neither allocate nor page-fault their working memory (the engine's
// per-batch scratch, the server's request buffers). take() hands out a lease
// that gives the object back when it goes out of scope; the pool keeps at
// most `capacity` spares and drops any the keep predicate refuses (so one
// huge call does not pin its memory for good).
//
// Thread-safety: take() and lease returns may run concurrently (one mutex,
// taken twice per call, never per ray). The pool must outlive its leases.
#pragma once

#include <cstddef>
#include <memory>
#include <mutex>
#include <utility>
#include <vector>

namespace outcore {

template <class T>
class ReusePool {
 public:
  // Whether a returned object is worth keeping (for example: small enough).
  using KeepPredicate = bool (*)(const T&);

  class Lease {
   public:
    Lease() = default;
    Lease(Lease&& other) noexcept = default;
    Lease& operator=(Lease&& other) noexcept {
      give_back();
      pool_ = std::exchange(other.pool_, nullptr);
      object_ = std::move(other.object_);
      return *this;
    }
    Lease(const Lease&) = delete;
    Lease& operator=(const Lease&) = delete;
    ~Lease() { give_back(); }

    T& operator*() const { return *object_; }
    T* operator->() const { return object_.get(); }
    T* get() const { return object_.get(); }

   private:
    friend class ReusePool;
    Lease(ReusePool* pool, std::unique_ptr<T> object) : pool_(pool), object_(std::move(object)) {}
    void give_back() {
      if (pool_ != nullptr && object_ != nullptr) pool_->give_back(std::move(object_));
      pool_ = nullptr;
    }

    ReusePool* pool_ = nullptr;
    std::unique_ptr<T> object_;
  };

  explicit ReusePool(std::size_t capacity, KeepPredicate keep = nullptr) : capacity_(capacity), keep_(keep) {}
  ReusePool(const ReusePool&) = delete;
  ReusePool& operator=(const ReusePool&) = delete;

  // A kept object (as its last user left it) or a new default-constructed one.
  Lease take() {
    {
      std::lock_guard lock(mutex_);
      if (!spares_.empty()) {
        std::unique_ptr<T> object = std::move(spares_.back());
        spares_.pop_back();
        return Lease(this, std::move(object));
      }
    }
    return Lease(this, std::make_unique<T>());
  }

  std::size_t spares() const {
    std::lock_guard lock(mutex_);
    return spares_.size();
  }

 private:
  void give_back(std::unique_ptr<T> object) {
    if (keep_ != nullptr && !keep_(*object)) return;
    std::lock_guard lock(mutex_);
    if (spares_.size() < capacity_) spares_.push_back(std::move(object));
  }

  const std::size_t capacity_;
  const KeepPredicate keep_;
  mutable std::mutex mutex_;
  std::vector<std::unique_ptr<T>> spares_;
};

}  // namespace outcore
