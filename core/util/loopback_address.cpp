#include "core/util/loopback_address.h"

#include <arpa/inet.h>

#include <algorithm>
#include <cstring>
#include <string>

namespace outcore {

std::string_view host_of(std::string_view host_port) {
  if (host_port.starts_with("[")) {
    const auto end = host_port.find(']');
    return end == std::string_view::npos ? std::string_view() : host_port.substr(1, end - 1);
  }
  if (std::count(host_port.begin(), host_port.end(), ':') == 1)
    return host_port.substr(0, host_port.find(':'));
  return host_port;
}

bool is_loopback_ip(std::string_view numeric_host) {
  // A scope ("fe80::1%eth0") is never loopback.
  if (numeric_host.find('%') != std::string_view::npos) return false;
  const std::string host(numeric_host);
  in_addr address4{};
  if (inet_pton(AF_INET, host.c_str(), &address4) == 1) return (ntohl(address4.s_addr) >> 24) == 127;
  in6_addr address6{};
  if (inet_pton(AF_INET6, host.c_str(), &address6) != 1) return false;
  if (IN6_IS_ADDR_LOOPBACK(&address6)) return true;
  return IN6_IS_ADDR_V4MAPPED(&address6) && address6.s6_addr[12] == 127;
}

}  // namespace outcore
