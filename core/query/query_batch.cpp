#include "core/query/query_batch.h"

#include <tbb/parallel_for.h>

#include <string>
#include <vector>

namespace outcore {
namespace {

// Rays per task when validating a batch.
constexpr std::size_t kCheckGrain = 16384;

}  // namespace

template <QueryKind kKind>
Status validate_batch(const QueryBatch<kKind>& batch, bool strict, uint64_t& invalid) {
  // The first bad ray of each chunk is kept so that strict mode names the
  // first of the batch.
  const std::size_t n = batch.size();
  const std::size_t chunks = (n + kCheckGrain - 1) / kCheckGrain;
  std::vector<uint64_t> chunk_invalid(chunks, 0);
  std::vector<std::size_t> chunk_first_bad(chunks, n);
  tbb::parallel_for(std::size_t{0}, chunks, [&](std::size_t c) {
    const std::size_t end = std::min(n, (c + 1) * kCheckGrain);
    for (std::size_t i = c * kCheckGrain; i < end; ++i) {
      const bool ok = batch.reset_and_check(i);
      batch.valid[i] = ok;
      if (!ok) {
        if (chunk_first_bad[c] == n) chunk_first_bad[c] = i;
        ++chunk_invalid[c];
      }
    }
  });
  for (std::size_t c = 0; c < chunks; ++c) {
    if (chunk_first_bad[c] != n && strict) {
      const std::size_t i = chunk_first_bad[c];
      return invalid_argument("ray " + std::to_string(i) + ": " + ray_problem(batch.rays[i]));
    }
    invalid += chunk_invalid[c];
  }
  return Status::Ok();
}

template Status validate_batch(const QueryBatch<QueryKind::kClosestHit>&, bool, uint64_t&);
template Status validate_batch(const QueryBatch<QueryKind::kAnyHit>&, bool, uint64_t&);
template Status validate_batch(const QueryBatch<QueryKind::kAllHits>&, bool, uint64_t&);

}  // namespace outcore
