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

Expected<std::unique_ptr<ReplicaRouter>> ReplicaRouter::connect(const std::vector<std::string>& addresses,
                                                                const ConnectOptions& options) {
  std::unique_ptr<ReplicaRouter> router(new ReplicaRouter());
  const std::vector<std::string> given = ReplicaRing(addresses).replicas();
  if (given.empty()) return invalid_argument("no replica given");
  Status first_error;
  for (const std::string& address : given) {
    if (address.empty()) return invalid_argument("an empty replica address in the list");
    auto client = SceneClient::connect(address, options);
    if (!client.ok()) {
      // Unreachable now: left out of the ring (a dns: name may list a pod
      // that is gone, or an address family the server does not listen on).
      if (client.status().code() != StatusCode::kIoError)
        return client.status().with_context("replica " + address);
      if (first_error.ok()) first_error = client.status().with_context("replica " + address);
      continue;
    }
    router->replicas_.push_back(address);
    router->clients_.push_back(std::move(*client));
  }
  if (router->clients_.empty()) return first_error;
  const v1::SceneInfo& info = router->clients_.front()->connected_scene();
  if (info.bounds_lo_size() == 3 && info.bounds_hi_size() == 3) {
    router->lo_ = {info.bounds_lo(0), info.bounds_lo(1), info.bounds_lo(2)};
    router->hi_ = {info.bounds_hi(0), info.bounds_hi(1), info.bounds_hi(2)};
  }
  return router;
}

std::vector<std::string> ReplicaRouter::replicas() const {
  return replicas_;
}

uint64_t ReplicaRouter::failovers() const {
  std::lock_guard lock(mutex_);
  return failovers_;
}

std::vector<uint32_t> ReplicaRouter::route(std::span<const Ray> rays) const {
  std::vector<std::string> live;
  std::vector<uint32_t> index_of_live;
  {
    std::lock_guard lock(mutex_);
    for (uint32_t r = 0; r < replicas_.size(); ++r) {
      if (!down_.contains(r)) {
        live.push_back(replicas_[r]);
        index_of_live.push_back(r);
      }
    }
  }
  std::vector<uint32_t> replica_of_ray(rays.size(), 0);
  if (live.empty()) return replica_of_ray;
  const ReplicaRing ring(live);  // sorted like replicas_, so indices map through index_of_live
  const std::vector<uint64_t> keys = route_keys(rays, lo_, hi_);
  std::map<uint64_t, uint64_t> counts;
  for (const uint64_t key : keys) ++counts[key];
  const std::map<uint64_t, uint32_t> owner = ring.assign(counts);
  for (std::size_t i = 0; i < rays.size(); ++i) replica_of_ray[i] = index_of_live[owner.at(keys[i])];
  return replica_of_ray;
}

std::vector<uint64_t> ReplicaRouter::plan_loads(std::span<const Ray> rays) const {
  std::vector<uint64_t> loads(replicas_.size(), 0);
  for (const uint32_t r : route(rays)) ++loads[r];
  return loads;
}

template <class Answer>
Status ReplicaRouter::run(std::span<const Ray> rays, std::span<Answer> out, const CallOptions& options,
                          CallStats* stats) {
  if (out.size() != rays.size()) return invalid_argument("answers and rays differ in length");
  {
    std::lock_guard lock(mutex_);
    if (down_.size() == replicas_.size()) down_.clear();  // all down: try them all again
  }
  const std::vector<uint32_t> replica_of_ray = route(rays);
  struct Part {
    uint32_t replica;
    std::vector<uint32_t> index;
    std::vector<Ray> rays;
    std::vector<Answer> answers;
    CallStats stats;
    Status status;
  };
  std::vector<Part> parts(replicas_.size());
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
      // A replica that cannot be reached: the part goes to the next on the ring.
      std::set<uint32_t> tried;
      while (true) {
        tried.insert(p->replica);
        p->stats = CallStats{};
        p->status = call(*clients_[p->replica], p->rays, p->answers, part_options, &p->stats);
        if (p->status.ok() || p->status.code() != StatusCode::kIoError) return;
        std::lock_guard lock(mutex_);
        down_.insert(p->replica);
        const std::vector<uint32_t> next = ReplicaRing(replicas_).walk(ring_hash(replicas_[p->replica]));
        const auto candidate = std::find_if(
            next.begin(), next.end(), [&](uint32_t r) { return !tried.contains(r) && !down_.contains(r); });
        if (candidate == next.end()) return;  // every replica failed: the part's error stands
        p->replica = *candidate;
        ++failovers_;
      }
    }));
  }
  for (auto& task : running) task.get();
  for (Part& part : parts) {
    if (part.index.empty()) continue;
    OUTCORE_RETURN_IF_ERROR(part.status.with_context("replica " + replicas_[part.replica]));
    for (std::size_t k = 0; k < part.index.size(); ++k) out[part.index[k]] = part.answers[k];
    add_call_stats(part.stats, stats);
  }
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
