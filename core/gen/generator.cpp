#include "core/gen/generator.h"

#include <memory>

namespace outcore {

Status Generator::stream(TriangleSink& sink) {
  // The batch buffer is ~150 KB: keep it off the (possibly small) thread stack.
  auto batcher = std::make_unique<TriangleBatcher>(sink);
  OUTCORE_RETURN_IF_ERROR(emit(*batcher));
  return batcher->finish();
}

}  // namespace outcore
