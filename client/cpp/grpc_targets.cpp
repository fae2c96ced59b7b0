#include "client/cpp/grpc_targets.h"

#include <string_view>

#include "core/util/loopback_address.h"

namespace outcore::client {

bool is_loopback_target(const std::string& address) {
  std::string_view target = address;
  if (target.starts_with("unix:") || target.starts_with("unix-abstract:")) return true;
  if (target.starts_with("ipv4:") || target.starts_with("ipv6:")) {
    // A comma-separated list: local only if every address is.
    target.remove_prefix(5);
    while (true) {
      const auto comma = target.find(',');
      if (!is_loopback_host(host_of(target.substr(0, comma)))) return false;
      if (comma == std::string_view::npos) return true;
      target.remove_prefix(comma + 1);
    }
  }
  if (target.starts_with("dns:")) {
    target.remove_prefix(4);
    if (target.starts_with("//")) {  // dns://authority/host:port
      const auto slash = target.find('/', 2);
      if (slash == std::string_view::npos) return false;
      target.remove_prefix(slash + 1);
    }
  }
  return is_loopback_host(host_of(target));
}

Status check_target_ports(const std::string& address) {
  std::string_view target = address;
  const auto check = [&](std::string_view host_port) -> Status {
    const auto port = port_of(host_port, 1);
    if (port.ok()) return Status::Ok();
    // The message quotes host_port; the whole target too when it is more.
    if (host_port == address) return invalid_argument("server address " + port.status().message());
    return invalid_argument("server address '" + address + "': " + port.status().message());
  };
  if (target.starts_with("ipv4:") || target.starts_with("ipv6:")) {
    target.remove_prefix(5);
    while (true) {
      const auto comma = target.find(',');
      OUTCORE_RETURN_IF_ERROR(check(target.substr(0, comma)));
      if (comma == std::string_view::npos) return Status::Ok();
      target.remove_prefix(comma + 1);
    }
  }
  if (target.starts_with("dns:")) {
    target.remove_prefix(4);
    if (target.starts_with("//")) {
      const auto slash = target.find('/', 2);
      if (slash == std::string_view::npos) return Status::Ok();  // gRPC names what is wrong
      target.remove_prefix(slash + 1);
    }
    return check(target);
  }
  // "name:rest" with a non-numeric rest is another scheme's target (unix:/path,
  // ...), with no port to check; "host:digits" is a bare HOST:PORT.
  const auto colon = target.find(':');
  const bool scheme = colon != std::string_view::npos && !target.starts_with("[") &&
                      target.find_first_not_of("abcdefghijklmnopqrstuvwxyz-") == colon &&
                      !target.substr(colon + 1).empty() &&
                      target.substr(colon + 1).find_first_not_of("0123456789") != std::string_view::npos;
  return scheme ? Status::Ok() : check(target);
}

}  // namespace outcore::client
