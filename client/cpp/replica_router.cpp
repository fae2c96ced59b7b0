#include "client/cpp/replica_router.h"

#include <arpa/inet.h>
#include <netdb.h>
#include <netinet/in.h>
#include <sys/socket.h>

#include <algorithm>
#include <future>
#include <map>

#include "client/cpp/replica_ring.h"
#include "core/util/loopback_address.h"
#include "proto/outcore/v1/query_stats_wire.h"

namespace outcore::client {

namespace {

// Sums a part's figures into the batch's.
void add_call_stats(const CallStats& part, CallStats* total) {
  if (total == nullptr) return;
  total->messages += part.messages;
  total->shared = total->shared || part.shared;
  wire::add_to_wire(wire::from_wire(part.engine), &total->engine);
}

Status call(SceneClient& client, std::span<const Ray> rays, std::span<Hit> out, const CallOptions& options,
            CallStats* stats) {
  return client.intersect(rays, out, options, stats);
}
Status call(SceneClient& client, std::span<const Ray> rays, std::span<uint8_t> out,
            const CallOptions& options, CallStats* stats) {
  return client.occluded(rays, out, options, stats);
}

// A part's answer merged into the batch's: the nearer hit under the
// engine's tie rule (smaller t, geometry id, primitive id); occlusion ORed.
void keep_nearest(Hit& into, const Hit& part) {
  if (part.is_hit() && hit_is_better(part.t, part.geometry_id, part.primitive_id, into)) into = part;
}
void keep_nearest(uint8_t& into, uint8_t part) {
  into = static_cast<uint8_t>(into | part);
}
bool answered_hit(const Hit& hit) {
  return hit.is_hit();
}
bool answered_hit(uint8_t occluded) {
  return occluded != 0;
}

}  // namespace

namespace {

// The addresses NAME resolves to, as HOST:PORT (IPv6 in brackets).
Expected<std::vector<std::string>> resolve_dns(const std::string& target) {
  std::string_view name = std::string_view(target).substr(4);  // after "dns:"
  while (name.starts_with("/")) name.remove_prefix(1);
  const Expected<uint16_t> port_number = port_of(name, 1);
  if (!port_number.ok()) return invalid_argument("server address " + port_number.status().message());
  const std::string host(host_of(name));
  const std::string port = std::to_string(*port_number);
  addrinfo hints{};
  hints.ai_socktype = SOCK_STREAM;
  addrinfo* found = nullptr;
  if (const int error = getaddrinfo(host.c_str(), port.c_str(), &hints, &found); error != 0) {
    return io_error("cannot resolve " + target + ": " + gai_strerror(error));
  }
  std::set<std::string> addresses;
  for (const addrinfo* a = found; a != nullptr; a = a->ai_next) {
    char ip[INET6_ADDRSTRLEN] = {};
    const void* where =
        a->ai_family == AF_INET6
            ? static_cast<const void*>(&reinterpret_cast<const sockaddr_in6*>(a->ai_addr)->sin6_addr)
            : static_cast<const void*>(&reinterpret_cast<const sockaddr_in*>(a->ai_addr)->sin_addr);
    if (inet_ntop(a->ai_family, where, ip, sizeof ip) == nullptr) continue;
    addresses.insert(a->ai_family == AF_INET6 ? "[" + std::string(ip) + "]:" + port
                                              : std::string(ip) + ":" + port);
  }
  freeaddrinfo(found);
  if (addresses.empty()) return io_error(target + " resolves to no address");
  return std::vector<std::string>(addresses.begin(), addresses.end());
}

}  // namespace

Expected<std::vector<std::string>> replica_list(const std::string& server) {
  if (server.starts_with("dns:")) {
    OUTCORE_ASSIGN_OR_RETURN(std::vector<std::string> resolved, resolve_dns(server));
    if (resolved.size() == 1) return std::vector<std::string>{};  // one server: gRPC's own channel
    return resolved;
  }
  if (server.find(',') == std::string::npos || server.starts_with("ipv4:") || server.starts_with("ipv6:")) {
    return std::vector<std::string>{};
  }
  std::vector<std::string> list;
  std::size_t at = 0;
  while (at <= server.size()) {
    const std::size_t comma = std::min(server.find(',', at), server.size());
    list.push_back(server.substr(at, comma - at));
    at = comma + 1;
  }
  return list;
}

Expected<std::shared_ptr<const ReplicaRouter::Members>> ReplicaRouter::join(
    const std::vector<std::string>& addresses, const Members* known) const {
  auto members = std::make_shared<Members>();
  const std::vector<std::string> given = ReplicaRing(addresses).replicas();
  if (given.empty()) return invalid_argument("no replica given");
  Status first_error;
  for (const std::string& address : given) {
    if (address.empty()) return invalid_argument("an empty replica address in the list");
    if (known != nullptr) {
      const auto it = std::find(known->replicas.begin(), known->replicas.end(), address);
      if (it != known->replicas.end()) {
        members->replicas.push_back(address);
        members->clients.push_back(known->clients[static_cast<std::size_t>(it - known->replicas.begin())]);
        continue;
      }
    }
    auto client = SceneClient::connect(address, options_);
    if (!client.ok()) {
      // Unreachable now: left out of the ring (a dns: name may list a pod
      // that is gone, or an address family the server does not listen on).
      if (client.status().code() != StatusCode::kIoError)
        return client.status().with_context("replica " + address);
      if (first_error.ok()) first_error = client.status().with_context("replica " + address);
      continue;
    }
    members->replicas.push_back(address);
    members->clients.push_back(std::move(*client));
  }
  if (members->clients.empty()) return first_error;
  return std::shared_ptr<const Members>(std::move(members));
}

Expected<std::unique_ptr<ReplicaRouter>> ReplicaRouter::connect(const std::vector<std::string>& addresses,
                                                                const ConnectOptions& options) {
  std::unique_ptr<ReplicaRouter> router(new ReplicaRouter());
  router->options_ = options;
  OUTCORE_ASSIGN_OR_RETURN(router->members_, router->join(addresses, nullptr));
  const v1::SceneInfo& info = router->members_->clients.front()->connected_scene();
  if (info.bounds_lo_size() == 3 && info.bounds_hi_size() == 3) {
    router->lo_ = {info.bounds_lo(0), info.bounds_lo(1), info.bounds_lo(2)};
    router->hi_ = {info.bounds_hi(0), info.bounds_hi(1), info.bounds_hi(2)};
  }
  for (int b = 0; b < info.bricks_size(); ++b) {
    const v1::BrickSummary& brick = info.bricks(b);
    if (brick.bounds_lo_size() != 3 || brick.bounds_hi_size() != 3)
      return data_loss("SceneInfo: brick " + std::to_string(b) + " has no box");
    const Vec3f lo{brick.bounds_lo(0), brick.bounds_lo(1), brick.bounds_lo(2)};
    const Vec3f hi{brick.bounds_hi(0), brick.bounds_hi(1), brick.bounds_hi(2)};
    router->bricks_.push_back(
        {brick_ring_position(static_cast<uint32_t>(b), lo, hi, router->lo_, router->hi_),
         std::max<uint64_t>(1, brick.triangle_count())});
  }
  if (router->bricks_.size() != info.brick_count()) {
    // A server from before SceneInfo.bricks: only routing by ray is possible.
    router->routing_ = ReplicaRouting::kRays;
    router->bricks_.clear();
  }
  return router;
}

Expected<std::unique_ptr<ReplicaRouter>> ReplicaRouter::connect_resolved(Resolver resolver,
                                                                         const ConnectOptions& options,
                                                                         std::chrono::milliseconds refresh) {
  OUTCORE_ASSIGN_OR_RETURN(const std::vector<std::string> addresses, resolver());
  OUTCORE_ASSIGN_OR_RETURN(std::unique_ptr<ReplicaRouter> router, connect(addresses, options));
  router->resolver_ = std::move(resolver);
  router->refresh_ = refresh;
  router->next_refresh_ = std::chrono::steady_clock::now() + refresh;
  return router;
}

Expected<std::unique_ptr<ReplicaRouter>> ReplicaRouter::connect_dns(const std::string& target,
                                                                    const ConnectOptions& options,
                                                                    std::chrono::milliseconds refresh) {
  if (!target.starts_with("dns:"))
    return invalid_argument("connect_dns: " + target + " is not a dns: target");
  return connect_resolved([target] { return resolve_dns(target); }, options, refresh);
}

std::shared_ptr<const ReplicaRouter::Members> ReplicaRouter::members() const {
  std::lock_guard lock(mutex_);
  return members_;
}

void ReplicaRouter::refresh_members() {
  if (!resolver_) return;
  std::lock_guard refreshing(refresh_mutex_);
  const auto now = std::chrono::steady_clock::now();
  if (now < next_refresh_) return;
  next_refresh_ = now + refresh_;
  const Expected<std::vector<std::string>> addresses = resolver_();
  if (!addresses.ok()) return;  // a resolver's hiccup: the replicas known stay
  const std::shared_ptr<const Members> current = members();
  if (ReplicaRing(*addresses).replicas() == current->replicas) return;
  Expected<std::shared_ptr<const Members>> joined = join(*addresses, current.get());
  if (!joined.ok()) return;  // none reachable now: keep those known
  std::lock_guard lock(mutex_);
  members_ = std::move(*joined);
  // Down marks of replicas that left the ring go with them.
  std::erase_if(down_, [&](const std::string& address) {
    return std::find(members_->replicas.begin(), members_->replicas.end(), address) ==
           members_->replicas.end();
  });
}

std::vector<std::string> ReplicaRouter::replicas() const {
  return members()->replicas;
}

uint64_t ReplicaRouter::failovers() const {
  std::lock_guard lock(mutex_);
  return failovers_;
}

std::vector<uint32_t> ReplicaRouter::live(const Members& members, std::vector<std::string>& names) const {
  std::vector<uint32_t> up;
  names.clear();
  std::lock_guard lock(mutex_);
  for (uint32_t r = 0; r < members.replicas.size(); ++r) {
    if (down_.contains(members.replicas[r])) continue;
    up.push_back(r);
    names.push_back(members.replicas[r]);
  }
  return up;
}

std::vector<std::vector<uint32_t>> ReplicaRouter::share_bricks(const Members& members) const {
  std::vector<std::string> names;
  const std::vector<uint32_t> index_of_live = live(members, names);
  std::vector<std::vector<uint32_t>> parts(members.replicas.size());
  if (index_of_live.empty()) return parts;
  const ReplicaRing ring(names, kBrickVirtualNodes);  // sorted like members.replicas
  std::map<uint64_t, uint64_t> weights;
  for (const BrickPlace& brick : bricks_) weights[brick.position] = brick.triangles;
  const std::map<uint64_t, uint32_t> owner = ring.assign(weights, kBrickLoadFactor);
  for (uint32_t b = 0; b < bricks_.size(); ++b)
    parts[index_of_live[owner.at(bricks_[b].position)]].push_back(b);
  return parts;
}

std::vector<std::vector<uint32_t>> ReplicaRouter::plan_bricks() const {
  return share_bricks(*members());
}

std::vector<uint32_t> ReplicaRouter::route(const Members& members, std::span<const Ray> rays) const {
  std::vector<std::string> names;
  const std::vector<uint32_t> index_of_live = live(members, names);
  std::vector<uint32_t> replica_of_ray(rays.size(), 0);
  if (index_of_live.empty()) return replica_of_ray;
  const ReplicaRing ring(names);  // sorted like members.replicas, so indices map through index_of_live
  const std::vector<uint64_t> keys = route_keys(rays, lo_, hi_);
  std::map<uint64_t, uint64_t> counts;
  for (const uint64_t key : keys) ++counts[key];
  const std::map<uint64_t, uint32_t> owner = ring.assign(counts);
  for (std::size_t i = 0; i < rays.size(); ++i) replica_of_ray[i] = index_of_live[owner.at(keys[i])];
  return replica_of_ray;
}

std::vector<uint64_t> ReplicaRouter::plan_loads(std::span<const Ray> rays) const {
  const std::shared_ptr<const Members> snapshot = members();
  std::vector<uint64_t> loads(snapshot->replicas.size(), 0);
  for (const uint32_t r : route(*snapshot, rays)) ++loads[r];
  return loads;
}

template <class Answer>
Status ReplicaRouter::run(std::span<const Ray> rays, std::span<Answer> out, const CallOptions& options,
                          CallStats* stats) {
  if (out.size() != rays.size()) return invalid_argument("answers and rays differ in length");
  refresh_members();
  const std::shared_ptr<const Members> snapshot = members();
  const Members& members = *snapshot;
  {
    std::lock_guard lock(mutex_);
    const bool all_down = std::all_of(members.replicas.begin(), members.replicas.end(),
                                      [&](const std::string& address) { return down_.contains(address); });
    if (all_down) down_.clear();  // all down: try them all again
  }
  if (routing_ == ReplicaRouting::kBricks) return run_by_bricks(members, rays, out, options, stats);
  const std::vector<uint32_t> replica_of_ray = route(members, rays);
  struct Part {
    uint32_t replica;
    std::vector<uint32_t> index;
    std::vector<Ray> rays;
    std::vector<Answer> answers;
    CallStats stats;
    Status status;
  };
  std::vector<Part> parts(members.replicas.size());
  for (uint32_t r = 0; r < parts.size(); ++r) parts[r].replica = r;
  for (uint32_t i = 0; i < replica_of_ray.size(); ++i) parts[replica_of_ray[i]].index.push_back(i);
  const CallOptions& part_options = options;
  std::vector<std::future<void>> running;
  for (Part& part : parts) {
    if (part.index.empty()) continue;
    part.rays.resize(part.index.size());
    for (std::size_t k = 0; k < part.index.size(); ++k) part.rays[k] = rays[part.index[k]];
    part.answers.resize(part.index.size());
    running.push_back(std::async(std::launch::async, [&, p = &part] {
      p->status =
          call_with_failover<Answer>(members, p->replica, p->rays, p->answers, part_options, p->stats);
    }));
  }
  for (auto& task : running) task.get();
  for (Part& part : parts) {
    if (part.index.empty()) continue;
    OUTCORE_RETURN_IF_ERROR(part.status.with_context("replica " + members.replicas[part.replica]));
    for (std::size_t k = 0; k < part.index.size(); ++k) out[part.index[k]] = part.answers[k];
    add_call_stats(part.stats, stats);
  }
  return Status::Ok();
}

template <class Answer>
Status ReplicaRouter::call_with_failover(const Members& members, uint32_t& replica, std::span<const Ray> rays,
                                         std::span<Answer> out, const CallOptions& options,
                                         CallStats& stats) {
  std::set<uint32_t> tried;
  while (true) {
    tried.insert(replica);
    stats = CallStats{};
    const Status status = call(*members.clients[replica], rays, out, options, &stats);
    if (status.ok() || status.code() != StatusCode::kIoError) return status;
    std::lock_guard lock(mutex_);
    down_.insert(members.replicas[replica]);
    const std::vector<uint32_t> next =
        ReplicaRing(members.replicas).walk(ring_hash(members.replicas[replica]));
    const auto candidate = std::find_if(next.begin(), next.end(), [&](uint32_t r) {
      return !tried.contains(r) && !down_.contains(members.replicas[r]);
    });
    if (candidate == next.end()) return status;  // every replica failed: the part's error stands
    replica = *candidate;
    ++failovers_;
  }
}

template <class Answer>
Status ReplicaRouter::run_by_bricks(const Members& members, std::span<const Ray> rays, std::span<Answer> out,
                                    const CallOptions& options, CallStats* stats) {
  struct Part {
    uint32_t replica;
    CallOptions options;
    std::vector<Answer> answers;
    CallStats stats;
    Status status;
  };
  const std::vector<std::vector<uint32_t>> shares = share_bricks(members);
  std::vector<Part> parts;
  for (uint32_t r = 0; r < shares.size(); ++r) {
    if (shares[r].empty()) continue;
    Part& part = parts.emplace_back(Part{r, options, {}, {}, {}});
    // A replica that owns every brick (the only one up) traces the whole
    // scene: no part, so the engine may use its every-brick strategies.
    if (shares[r].size() != bricks_.size()) part.options.only_bricks = shares[r];
    part.options.progress = nullptr;  // one part's progress is not the batch's
  }
  // The first part answers into `out`, the others into their own, merged.
  for (std::size_t k = 1; k < parts.size(); ++k) parts[k].answers.resize(rays.size());
  std::vector<std::future<void>> running;
  for (std::size_t k = 0; k < parts.size(); ++k) {
    running.push_back(std::async(std::launch::async, [&, p = &parts[k], k] {
      const std::span<Answer> answers = k == 0 ? out : std::span<Answer>(p->answers);
      p->status = call_with_failover<Answer>(members, p->replica, rays, answers, p->options, p->stats);
    }));
  }
  for (auto& task : running) task.get();
  for (std::size_t k = 0; k < parts.size(); ++k) {
    Part& part = parts[k];
    OUTCORE_RETURN_IF_ERROR(part.status.with_context("replica " + members.replicas[part.replica]));
    if (k > 0) {
      for (std::size_t i = 0; i < rays.size(); ++i) keep_nearest(out[i], part.answers[i]);
    }
    add_call_stats(part.stats, stats);
  }
  if (stats != nullptr && !parts.empty()) {
    // Every replica saw every ray: the batch's own counts, not their sum.
    const v1::QueryStats& first = parts.front().stats.engine;
    stats->engine.set_rays(first.rays());
    stats->engine.set_invalid_rays(first.invalid_rays());
    uint64_t hit = 0;
    for (const Answer& answer : out) hit += answered_hit(answer);
    stats->engine.set_rays_hit(hit);
  }
  if (options.progress != nullptr) options.progress->advance(rays.size());
  return Status::Ok();
}

Status ReplicaRouter::intersect(std::span<const Ray> rays, std::span<Hit> hits, const CallOptions& options,
                                CallStats* stats) {
  return run<Hit>(rays, hits, options, stats);
}

Status ReplicaRouter::occluded(std::span<const Ray> rays, std::span<uint8_t> occluded,
                               const CallOptions& options, CallStats* stats) {
  return run<uint8_t>(rays, occluded, options, stats);
}

}  // namespace outcore::client
