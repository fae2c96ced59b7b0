#include "core/gen/gen_spec.h"

#include <algorithm>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <cstdlib>

namespace outcore {

namespace {

constexpr std::string_view kPrefix = "gen:";

int hex_digit(char c) {
  if (c >= '0' && c <= '9') return c - '0';
  if (c >= 'a' && c <= 'f') return c - 'a' + 10;
  if (c >= 'A' && c <= 'F') return c - 'A' + 10;
  return -1;
}

std::string format_real(double v) {
  char buf[64];
  std::snprintf(buf, sizeof buf, "%.17g", v);
  // Prefer the shortest form that reads back exactly.
  for (int precision = 1; precision < 17; ++precision) {
    char shorter[64];
    std::snprintf(shorter, sizeof shorter, "%.*g", precision, v);
    if (std::strtod(shorter, nullptr) == v) return shorter;
  }
  return buf;
}

}  // namespace

std::string_view gen_spec_name(std::string_view spec) {
  if (!spec.starts_with(kPrefix)) return {};
  spec.remove_prefix(kPrefix.size());
  return spec.substr(0, spec.find('?'));
}

Expected<GenSpec> parse_gen_spec(std::string_view spec) {
  if (!spec.starts_with(kPrefix)) {
    return invalid_argument("generator spec '" + std::string(spec) + "' does not start with 'gen:'");
  }
  GenSpec out;
  out.text = std::string(spec);
  out.name = std::string(gen_spec_name(spec));
  if (out.name.empty()) {
    return invalid_argument("generator spec '" + out.text +
                            "' has no generator name (gen:NAME?key=value&...)");
  }
  const std::string where = "gen:" + out.name;
  std::size_t pos = kPrefix.size() + out.name.size();
  if (pos == spec.size()) return out;  // no '?'
  ++pos;                               // skip '?'
  if (pos == spec.size()) return invalid_argument(where + ": empty parameter list after '?'");

  while (true) {
    // Key: up to '=' (or a premature '&' / end).
    const std::size_t key_end = spec.find_first_of("=&", pos);
    const std::string key(
        spec.substr(pos, key_end == std::string_view::npos ? std::string_view::npos : key_end - pos));
    if (key.empty()) {
      return invalid_argument(where + ": empty parameter name at position " + std::to_string(pos) +
                              " (expected key=value)");
    }
    if (key_end == std::string_view::npos || spec[key_end] != '=') {
      return invalid_argument(where + ": parameter '" + key + "' has no value (expected " + key + "=value)");
    }
    for (const GenParam& p : out.params) {
      if (p.key == key) return invalid_argument(where + ": parameter '" + key + "' is given twice");
    }
    pos = key_end + 1;

    // Value: parenthesised (literal, nesting) or plain (percent-decoded).
    std::string value;
    if (pos < spec.size() && spec[pos] == '(') {
      int depth = 0;
      std::size_t i = pos;
      for (; i < spec.size(); ++i) {
        if (spec[i] == '(') ++depth;
        if (spec[i] == ')' && --depth == 0) break;
      }
      if (i == spec.size()) {
        return invalid_argument(where + ": parameter '" + key + "': unbalanced '(' in value");
      }
      value = std::string(spec.substr(pos + 1, i - pos - 1));
      pos = i + 1;
      if (pos < spec.size() && spec[pos] != '&') {
        return invalid_argument(
            where + ": parameter '" + key +
            "': unexpected text after ')' (a parenthesised value must end the parameter)");
      }
    } else {
      const std::size_t end = std::min(spec.find('&', pos), spec.size());
      for (std::size_t i = pos; i < end; ++i) {
        if (spec[i] != '%') {
          value.push_back(spec[i]);
          continue;
        }
        const int hi = i + 1 < end ? hex_digit(spec[i + 1]) : -1;
        const int lo = i + 2 < end ? hex_digit(spec[i + 2]) : -1;
        if (hi < 0 || lo < 0) {
          return invalid_argument(where + ": parameter '" + key +
                                  "': malformed percent-escape (expected %XX with two hex digits)");
        }
        value.push_back(static_cast<char>(hi * 16 + lo));
        i += 2;
      }
      pos = end;
    }
    out.params.push_back({key, std::move(value)});

    if (pos == spec.size()) break;
    ++pos;  // skip '&'
    if (pos == spec.size()) return invalid_argument(where + ": empty parameter after trailing '&'");
  }
  return out;
}

std::string RealRange::to_string() const {
  return std::string(lo_open ? "(" : "[") + format_real(lo) + ", " + format_real(hi) + (hi_open ? ")" : "]");
}

GenParams::GenParams(const GenSpec& spec) : spec_(spec) {}

const GenParam* GenParams::find(std::string_view key) {
  known_.emplace_back(key);
  for (const GenParam& p : spec_.params) {
    if (p.key == key) return &p;
  }
  return nullptr;
}

bool GenParams::has(std::string_view key) const {
  return std::any_of(spec_.params.begin(), spec_.params.end(),
                     [&](const GenParam& p) { return p.key == key; });
}

Status GenParams::param_error(std::string_view key, const std::string& what) const {
  return invalid_argument("gen:" + spec_.name + ": parameter '" + std::string(key) + "' " + what);
}

void GenParams::fail(std::string_view key, const std::string& what) {
  if (first_error_.ok()) first_error_ = param_error(key, what);
}

void GenParams::integer(std::string_view key, int64_t& value, int64_t lo, int64_t hi) {
  const GenParam* p = find(key);
  if (p == nullptr) return;
  int64_t v = 0;
  const char* first = p->value.data();
  const char* last = first + p->value.size();
  const auto [end, ec] = std::from_chars(first, last, v);
  if (ec == std::errc::result_out_of_range) {
    return fail(
        key, "= '" + p->value + "' is out of range [" + std::to_string(lo) + ", " + std::to_string(hi) + "]");
  }
  if (ec != std::errc() || end != last) {
    return fail(key, "= '" + p->value + "' is not an integer");
  }
  if (v < lo || v > hi) {
    return fail(key, "= " + std::to_string(v) + " is out of range [" + std::to_string(lo) + ", " +
                         std::to_string(hi) + "]");
  }
  value = v;
}

void GenParams::integer(std::string_view key, int& value, int lo, int hi) {
  int64_t v = value;
  integer(key, v, lo, hi);
  value = static_cast<int>(v);
}

void GenParams::real(std::string_view key, std::optional<double>& value, RealRange range) {
  const GenParam* p = find(key);
  if (p == nullptr) return;
  double v = 0;
  const char* first = p->value.data();
  const char* last = first + p->value.size();
  const auto [end, ec] = std::from_chars(first, last, v);
  if ((ec != std::errc() && ec != std::errc::result_out_of_range) || end != last) {
    return fail(key, "= '" + p->value + "' is not a number");
  }
  if (ec == std::errc::result_out_of_range || !std::isfinite(v) || !range.contains(v)) {
    return fail(key, "= " + p->value + " is out of range " + range.to_string());
  }
  value = v;
}

void GenParams::real(std::string_view key, double& value, RealRange range) {
  std::optional<double> v;
  real(key, v, range);
  if (v) value = *v;
}

void GenParams::text(std::string_view key, std::string& value) {
  const GenParam* p = find(key);
  if (p == nullptr) return;
  if (p->value.empty()) return fail(key, "is empty");
  value = p->value;
}

Status GenParams::finish() const {
  if (!first_error_.ok()) return first_error_;
  for (const GenParam& p : spec_.params) {
    if (std::find(known_.begin(), known_.end(), p.key) != known_.end()) continue;
    std::string known;
    for (const std::string& k : known_) known += (known.empty() ? "" : ", ") + k;
    return invalid_argument("gen:" + spec_.name + ": unknown parameter '" + p.key +
                            "' (known: " + (known.empty() ? "none" : known) + ")");
  }
  return Status::Ok();
}

}  // namespace outcore
