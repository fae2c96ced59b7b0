// The queued strategy's first pass: every ray's first brick, found in
// parallel chunks (8 rays at a time through the upper hierarchy where they
// share a direction octant), and the ray queued there. A ray that enters no
// brick is answered there (a miss) and never queued (RayWalk::start).
#pragma once

#include "core/query/brick_queues.h"
#include "core/query/strategy.h"

namespace outcore {

// Also validates and resets the rays unless they were validated apart (one
// pass less over their memory).
template <QueryKind kKind>
void queue_first_bricks(StrategyContext<kKind>& ctx, BrickQueues& queues);

}  // namespace outcore
