#include "core/query/brick_visit.h"

namespace outcore {

Status acquire_brick(BrickCache& cache, uint32_t brick, uint64_t rays, PinnedBrick& pin, BatchTally& tally,
                     uint64_t rays_ahead) {
  const auto t0 = Clock::now();
  auto acquired = cache.acquire(brick, rays, rays_ahead);
  tally.stats.seconds_build += seconds_since(t0);
  if (!acquired.ok()) return acquired.status();
  pin = std::move(acquired).value();
  tally.add_acquisition(pin.was_hit());
  return Status::Ok();
}

std::optional<PinnedBrick> pin_for(BrickCache& cache, uint32_t brick, uint64_t rays, PinningTask& task,
                                   uint64_t rays_ahead) {
  const auto t0 = Clock::now();
  auto acquired = cache.acquire(brick, rays, rays_ahead);
  task.build_seconds = seconds_since(t0);
  if (!acquired.ok()) {
    task.status = acquired.status();
    return std::nullopt;
  }
  task.was_hit = acquired->was_hit();
  return std::move(acquired).value();
}

}  // namespace outcore
