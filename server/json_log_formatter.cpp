#include "server/json_log_formatter.h"

#include <spdlog/details/log_msg.h>

#include <chrono>
#include <cstdio>
#include <ctime>
#include <string>

#include "core/util/json_writer.h"

namespace outcore::server {

void JsonLogFormatter::format(const spdlog::details::log_msg& msg, spdlog::memory_buf_t& dest) {
  const auto since_epoch = msg.time.time_since_epoch();
  const std::time_t seconds = std::chrono::duration_cast<std::chrono::seconds>(since_epoch).count();
  const auto micros = std::chrono::duration_cast<std::chrono::microseconds>(since_epoch).count() % 1'000'000;
  std::tm utc{};
  gmtime_r(&seconds, &utc);
  char time_text[48];
  std::snprintf(time_text, sizeof time_text, "%04d-%02d-%02dT%02d:%02d:%02d.%06lldZ", utc.tm_year + 1900,
                utc.tm_mon + 1, utc.tm_mday, utc.tm_hour, utc.tm_min, utc.tm_sec,
                static_cast<long long>(micros));
  const spdlog::string_view_t level = spdlog::level::to_string_view(msg.level);
  JsonWriter record;
  record.begin_object()
      .field("time", std::string_view(time_text))
      .field("level", std::string_view(level.data(), level.size()))
      .field("logger", std::string_view(msg.logger_name.data(), msg.logger_name.size()))
      .field("message", std::string_view(msg.payload.data(), msg.payload.size()))
      .end_object();
  const std::string line = record.str() + "\n";
  dest.append(line.data(), line.data() + line.size());
}

std::unique_ptr<spdlog::formatter> JsonLogFormatter::clone() const {
  return std::make_unique<JsonLogFormatter>();
}

}  // namespace outcore::server
