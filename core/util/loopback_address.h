// Whether a network address names this host, for the same-host shared
// payloads: the server checks the peer gRPC reports (server/shared_payload.h)
// and the clients check the target they were given (client/cpp/scene_client.h),
// with the same rules for the address itself.
//
// Thread-safety: pure functions.
#pragma once

#include <string_view>

namespace outcore {

// "[v6]:port" -> "v6", "host:port" -> "host"; anything else (a bare host, a
// bare IPv6 address) as it is. An unclosed '[' gives "".
std::string_view host_of(std::string_view host_port);

// True for a numeric loopback address: IPv4 127.0.0.0/8, IPv6 ::1, and
// IPv4-mapped ::ffff:127.x.y.z. Names (even "localhost"), scoped IPv6
// addresses and anything unparsable are false.
bool is_loopback_ip(std::string_view numeric_host);

}  // namespace outcore
