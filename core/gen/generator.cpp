#include "core/gen/generator.h"

#include <algorithm>
#include <memory>

namespace outcore {

Status Generator::stream(TriangleSink& sink) {
  // The batch buffer is ~150 KB: keep it off the (possibly small) thread stack.
  auto batcher = std::make_unique<TriangleBatcher>(sink);
  OUTCORE_RETURN_IF_ERROR(emit(*batcher));
  return batcher->finish();
}

Status Generator::emit_range(uint64_t first, uint64_t last, TriangleBatcher& out) const {
  if (first == 0 && last >= triangle_count()) return emit(out);
  uint64_t next = 0;
  auto keep = CallbackSink([&](std::span<const Triangle> batch) -> Status {
    const uint64_t begin = next, end = next + batch.size();
    next = end;
    const uint64_t lo = std::max(begin, first), hi = std::min(end, last);
    for (uint64_t k = lo; k < hi; ++k) OUTCORE_RETURN_IF_ERROR(out.add(batch[k - begin]));
    return Status::Ok();
  });
  auto batcher = std::make_unique<TriangleBatcher>(keep);
  OUTCORE_RETURN_IF_ERROR(emit(*batcher));
  return batcher->finish();
}

}  // namespace outcore
