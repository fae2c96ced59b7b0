// GenSpec: a parsed generator spec `gen:NAME` or `gen:NAME?key=value&key2=value2`,
// and GenParams, the typed, range-checked way a generator reads its parameters.
//
// Syntax:
//   - NAME is everything between "gen:" and the first '?'.
//   - Parameters are separated by '&'; each is key=value (the first '=' splits).
//   - A value is percent-decoded once (%26 -> '&', %3F -> '?', %3D -> '=',
//     %28/%29 -> '(' / ')', %25 -> '%'; '+' stays '+').
//   - A value that starts with '(' runs to the matching ')' (parentheses nest)
//     and is taken literally, without percent-decoding, so that a nested spec
//     keeps its own syntax: gen:city?of=(gen:sphere?level=2&radius=3)&copies=100.
//     The ')' must be followed by '&' or the end.
//   - Malformed syntax, an empty key or a duplicated key is INVALID_ARGUMENT
//     naming the generator and the parameter.
//
// GenParams: a generator declares each parameter it knows with a default and a
// range; after all declarations, finish() reports the first malformed or
// out-of-range value, else any parameter nobody declared (listing the known
// ones). Every message names the generator and the parameter.
//
// Thread-safety: GenSpec is a plain value; a GenParams is used by one thread.
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "core/util/status.h"

namespace outcore {

struct GenParam {
  std::string key;
  std::string value;  // decoded
};

struct GenSpec {
  std::string text;              // the spec as written
  std::string name;              // the generator's name
  std::vector<GenParam> params;  // in the order written, keys unique
};

// The NAME part of "gen:NAME?..." (empty if `spec` does not start with "gen:").
std::string_view gen_spec_name(std::string_view spec);

// Parses the syntax above; does not check the name or the keys against any
// generator.
Expected<GenSpec> parse_gen_spec(std::string_view spec);

// A closed, half-open or open interval of reals, for range checks and messages.
struct RealRange {
  double lo;
  double hi;
  bool lo_open = false;
  bool hi_open = false;

  // Limits keep every derived coordinate finite in float.
  static constexpr double kLimit = 1e30;
  static RealRange any() { return {-kLimit, kLimit}; }
  static RealRange positive() { return {0.0, kLimit, true, false}; }
  static RealRange closed(double lo, double hi) { return {lo, hi}; }
  bool contains(double v) const { return (lo_open ? v > lo : v >= lo) && (hi_open ? v < hi : v <= hi); }
  std::string to_string() const;
};

class GenParams {
 public:
  explicit GenParams(const GenSpec& spec);

  // Each call declares the parameter `key`; if the spec gives it, the value is
  // parsed and range-checked into `value`, else `value` keeps its default.
  void integer(std::string_view key, int64_t& value, int64_t lo, int64_t hi);
  void integer(std::string_view key, int& value, int lo, int hi);
  void real(std::string_view key, double& value, RealRange range);
  void real(std::string_view key, std::optional<double>& value, RealRange range);
  void text(std::string_view key, std::string& value);

  // True if the spec gives `key` (declared or not).
  bool has(std::string_view key) const;

  // A custom check (e.g. one parameter against another); reported by finish()
  // as INVALID_ARGUMENT "gen:NAME: parameter 'key' <what>" unless an earlier
  // error is already pending.
  void fail(std::string_view key, const std::string& what);

  // The first error in declaration order, or an unknown-parameter error, or OK.
  Status finish() const;

 private:
  const GenParam* find(std::string_view key);
  Status param_error(std::string_view key, const std::string& what) const;

  const GenSpec& spec_;
  std::vector<std::string> known_;
  Status first_error_;
};

}  // namespace outcore
