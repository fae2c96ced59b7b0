#include "server/shared_payload.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <atomic>
#include <cstdlib>
#include <mutex>
#include <string>
#include <tuple>

#include "core/util/loopback_address.h"
#include "server/ray_batch.h"

namespace outcore::server {
namespace {

// Rays per step of the copies: small enough for an F32X6 step to stay in
// cache between its copy and its widening, large enough that the steps'
// overhead vanishes next to 96-128 KiB of copying.
constexpr uint64_t kStepRays = 4096;

// Bytes per step when copying the answers in.
constexpr uint64_t kStepBytes = uint64_t{128} << 10;

// Runs step(first, count) over [0, n) in steps of `step_size` on the engine's
// threads (the copies of a 1 M-ray batch take milliseconds each, which one
// thread would add to the call); the first error wins.
template <class Step>
Status for_each_step(uint64_t n, uint64_t step_size, const Step& step) {
  std::atomic<bool> failed{false};
  std::mutex error_mutex;
  Status error;
  tbb::parallel_for(tbb::blocked_range<uint64_t>(0, (n + step_size - 1) / step_size),
                    [&](const tbb::blocked_range<uint64_t>& steps) {
                      for (uint64_t s = steps.begin(); s != steps.end(); ++s) {
                        if (failed.load(std::memory_order_relaxed)) return;
                        const uint64_t first = s * step_size;
                        Status status = step(first, std::min(step_size, n - first));
                        if (!status.ok()) {
                          std::lock_guard lock(error_mutex);
                          if (!failed.exchange(true)) error = std::move(status);
                          return;
                        }
                      }
                    });
  return error;
}

// Both ranges are known to end at or below 2^63 (checked before), so the sums
// cannot wrap.
bool ranges_overlap(uint64_t a, uint64_t a_bytes, uint64_t b, uint64_t b_bytes) {
  return a_bytes != 0 && b_bytes != 0 && a < b + b_bytes && b < a + a_bytes;
}

std::string range_text(uint64_t offset, uint64_t bytes) {
  return "[" + std::to_string(offset) + ", " + std::to_string(offset) + " + " + std::to_string(bytes) + ")";
}

std::string percent_decoded(std::string_view text) {
  std::string out;
  out.reserve(text.size());
  for (std::size_t i = 0; i < text.size(); ++i) {
    if (text[i] == '%' && i + 2 < text.size()) {
      const std::string hex(text.substr(i + 1, 2));
      char* end = nullptr;
      const long value = std::strtol(hex.c_str(), &end, 16);
      if (end == hex.c_str() + 2) {
        out.push_back(static_cast<char>(value));
        i += 2;
        continue;
      }
    }
    out.push_back(text[i]);
  }
  return out;
}

}  // namespace

bool is_loopback_peer(std::string_view peer) {
  if (peer.starts_with("unix:") || peer.starts_with("unix-abstract:")) return true;
  if (!peer.starts_with("ipv4:") && !peer.starts_with("ipv6:")) return false;
  const std::string address = percent_decoded(peer.substr(5));
  return is_loopback_ip(host_of(address));
}

Expected<std::shared_ptr<SharedMemoryObject>> open_shared_payload(const v1::QueryRequest& request,
                                                                  uint64_t answer_bytes_per_ray,
                                                                  SharedMappingCache& mappings,
                                                                  uint64_t answers_room) {
  const v1::RayBatch& batch = request.batch();
  const v1::SharedPayload& payload = request.shared();
  OUTCORE_ASSIGN_OR_RETURN(const uint32_t ray_bytes, check_batch_layout(batch));
  if (!batch.rays().empty()) {
    return invalid_argument("batch.rays holds " + std::to_string(batch.rays().size()) +
                            " bytes but the request has a shared payload; leave batch.rays empty");
  }
  OUTCORE_RETURN_IF_ERROR(SharedMemoryObject::check_name(payload.name()).with_context("shared.name"));
  const uint64_t n = batch.ray_count();
  // Bounds every sum below far from wrapping; no object holds that many.
  constexpr uint64_t kMaxOffset = uint64_t{1} << 62;
  if (n > (uint64_t{1} << 56)) {
    return invalid_argument("batch.ray_count " + std::to_string(n) + " is beyond any shared-memory object");
  }
  const uint64_t rays_bytes = n * ray_bytes;
  if (answers_room != 0 && (answers_room > kMaxOffset || answers_room < n * answer_bytes_per_ray)) {
    return invalid_argument("shared.answers_bytes is " + std::to_string(answers_room) + "; " +
                            std::to_string(n) + " rays need at least " +
                            std::to_string(n * answer_bytes_per_ray));
  }
  const uint64_t answers_bytes = answers_room != 0 ? answers_room : n * answer_bytes_per_ray;
  uint64_t map_bytes = SharedMemoryObject::kHeaderBytes;
  for (const auto& [what, offset, bytes] :
       {std::tuple{"rays_offset", payload.rays_offset(), rays_bytes},
        std::tuple{"answers_offset", payload.answers_offset(), answers_bytes}}) {
    if (offset < SharedMemoryObject::kHeaderBytes) {
      return invalid_argument(std::string("shared.") + what + " is " + std::to_string(offset) +
                              ", inside the object's " + std::to_string(SharedMemoryObject::kHeaderBytes) +
                              "-byte header");
    }
    if (offset > kMaxOffset) {
      return invalid_argument(std::string("shared.") + what + " " + std::to_string(offset) +
                              " is not inside any shared-memory object");
    }
    map_bytes = std::max(map_bytes, offset + bytes);
  }
  if (ranges_overlap(payload.rays_offset(), rays_bytes, payload.answers_offset(), answers_bytes)) {
    return invalid_argument("shared: the rays " + range_text(payload.rays_offset(), rays_bytes) +
                            " and the answers " + range_text(payload.answers_offset(), answers_bytes) +
                            " overlap");
  }
  auto object = mappings.open(payload.name(), map_bytes);
  if (!object.ok()) {
    // A FIFO or a link under the name is no client's object: an error, not
    // a reason to send bytes. Missing objects and other users' (a client
    // running as another user) are: the client then sends bytes.
    if (object.status().code() == StatusCode::kInvalidArgument)
      return object.status().with_context("shared.name");
    return failed_precondition(object.status().message());
  }
  for (const auto& [what, offset, bytes] : {std::tuple{"rays", payload.rays_offset(), rays_bytes},
                                            std::tuple{"answers", payload.answers_offset(), answers_bytes}}) {
    if (offset > (*object)->size() || bytes > (*object)->size() - offset) {
      return invalid_argument(std::string("shared: the ") + what + " " + range_text(offset, bytes) +
                              " are not inside " + payload.name() + " (" + std::to_string((*object)->size()) +
                              " bytes)");
    }
  }
  OUTCORE_RETURN_IF_ERROR((*object)->check_token(payload.token()).with_context("shared.token"));
  return object;
}

Status read_shared_rays(const SharedMemoryObject& object, const v1::QueryRequest& request, uint64_t first,
                        uint64_t count, std::vector<Ray>& storage) {
  const uint32_t ray_bytes = ray_layout_bytes(request.batch().ray_layout());
  if (storage.size() < count) storage.resize(count);
  const uint64_t rays_at = request.shared().rays_offset() + first * ray_bytes;
  return for_each_step(count, kStepRays, [&](uint64_t step_first, uint64_t step_count) -> Status {
    if (ray_bytes == sizeof(Ray)) {
      return object.copy_out(rays_at + step_first * sizeof(Ray), &storage[step_first],
                             step_count * sizeof(Ray));
    }
    char rows[kStepRays * 24];
    OUTCORE_RETURN_IF_ERROR(object.copy_out(rays_at + step_first * 24, rows, step_count * 24));
    widen_f32x6(rows, step_count, storage.data() + step_first);
    return Status::Ok();
  });
}

Status write_shared_answers(SharedMemoryObject& object, const v1::SharedPayload& payload, uint64_t first_byte,
                            std::span<const uint8_t> answers) {
  const uint64_t answers_at = payload.answers_offset() + first_byte;
  return for_each_step(answers.size(), kStepBytes, [&](uint64_t step_first, uint64_t step_count) {
    return object.copy_in(answers_at + step_first, answers.data() + step_first, step_count);
  });
}

}  // namespace outcore::server
