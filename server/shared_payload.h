// Same-host shared payloads (proto SharedPayload): a unary call's rays read
// from, and its answers written to, a POSIX shared-memory object the client
// created, instead of the request's and reply's bytes fields. Only loopback
// peers may use them, and only with the object's token (the object is named,
// not passed: anyone who can list /dev/shm knows the names).
//
// The rays are copied out of the object and the answers into it with the
// SIGBUS-guarded copies of core/util/shared_memory.h: the engine never
// traces from memory the client can truncate. The service traces a shared
// call in groups of kSharedGroupRays, so its own buffers stay bounded
// whatever the batch.
//
// Thread-safety: free functions, reentrant.
#pragma once

#include <cstdint>
#include <span>
#include <string_view>
#include <vector>

#include "core/ray/ray_types.h"
#include "core/util/shared_memory.h"
#include "core/util/status.h"
#include "outcore/v1/scene_query.pb.h"
#include "server/shared_mapping_cache.h"

namespace outcore::server {

// Most rays of a shared call traced in one engine call (and held in the
// server's buffers at once): 64 MiB of rays and 32 MiB of hits.
inline constexpr uint64_t kSharedGroupRays = uint64_t{1} << 20;

// True for gRPC peer strings of this host: "ipv4:127.x.y.z:port", IPv6
// loopback as gRPC writes it ("ipv6:%5B::1%5D:port", also unescaped),
// IPv4-mapped 127.x, "unix:..." and "unix-abstract:...".
bool is_loopback_peer(std::string_view peer);

// Checks the request's batch and shared payload, opens the object through
// `mappings` (mapping only what its ranges need, or reusing the mapping of an
// earlier call on the same object) and checks its token. INVALID_ARGUMENT for a
// malformed batch or payload (layout, count, non-empty batch.rays, a bad
// name, ranges inside the header, outside the object or overlapping);
// INVALID_ARGUMENT naming the object when it is not a regular file (a FIFO,
// a symbolic link: refused without waiting on it); PERMISSION_DENIED for a
// token that does not match; FAILED_PRECONDITION when the object cannot be
// opened or belongs to another user (a client then sends bytes).
// `answers_room`: the answers range's size when the call's answers have no
// fixed size per ray (ListIntersections: shared.answers_bytes, checked to
// hold answer_bytes_per_ray a ray); 0: ray_count x answer_bytes_per_ray.
Expected<std::shared_ptr<SharedMemoryObject>> open_shared_payload(const v1::QueryRequest& request,
                                                                  uint64_t answer_bytes_per_ray,
                                                                  SharedMappingCache& mappings,
                                                                  uint64_t answers_room = 0);

// Copies rays [first, first + count) of the batch out of the object into
// `storage` (resized to at least `count`; F32X6 widened).
// FAILED_PRECONDITION when the object shrank meanwhile.
Status read_shared_rays(const SharedMemoryObject& object, const v1::QueryRequest& request, uint64_t first,
                        uint64_t count, std::vector<Ray>& storage);

// Writes `answers` at byte `first_byte` of the payload's answers range;
// FAILED_PRECONDITION when the object shrank meanwhile.
Status write_shared_answers(SharedMemoryObject& object, const v1::SharedPayload& payload, uint64_t first_byte,
                            std::span<const uint8_t> answers);

}  // namespace outcore::server
