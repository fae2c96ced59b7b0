// `serve --log-format json`: each log record as one JSON object on one line,
// {"time": RFC 3339 UTC with microseconds, "level", "logger", "message"},
// for log collectors (Loki, Elasticsearch, Cloud Logging) that parse lines
// instead of scraping text.
//
// Thread-safety: as any spdlog formatter (each sink owns its clone).
#pragma once

#include <spdlog/formatter.h>

#include <memory>
#include <string>
#include <string_view>

namespace outcore::server {

class JsonLogFormatter final : public spdlog::formatter {
 public:
  void format(const spdlog::details::log_msg& msg, spdlog::memory_buf_t& dest) override;
  std::unique_ptr<spdlog::formatter> clone() const override;
};

}  // namespace outcore::server
