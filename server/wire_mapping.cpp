#include "server/wire_mapping.h"

#include <string_view>

namespace outcore::server {

std::string where(const BatchPosition& position) {
  return position.streamed ? "chunk " + std::to_string(position.chunk) : std::string("request");
}

void set_answered_sums(const QueryStats& answered, v1::ServerStats* out) {
  // ServerStats names each sum as QueryStats does, except seconds_total's.
  out->set_seconds_tracing(answered.seconds_total);
  // A generic lambda, so that the setters of figures not summed (which
  // ServerStats lacks) sit in discarded branches and are never instantiated.
  const auto set = [&answered](auto* stats) {
#define OUTCORE_SET_SERVER_SUM(type, name, object, key, combine, wire, server)                          \
  if constexpr (StatsServer::server == StatsServer::kYes && std::string_view(#name) != "seconds_total") \
    stats->set_##name(answered.name);
    OUTCORE_QUERY_STATS(OUTCORE_SET_SERVER_SUM)
#undef OUTCORE_SET_SERVER_SUM
  };
  set(out);
}

}  // namespace outcore::server
