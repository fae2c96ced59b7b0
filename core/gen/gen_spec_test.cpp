#include "core/gen/gen_spec.h"

#include <gtest/gtest.h>

#include <optional>

namespace outcore {
namespace OUTCORE_UNITY_ID {

GenSpec parse_ok(const std::string& text) {
  auto s = parse_gen_spec(text);
  EXPECT_TRUE(s.ok()) << text << ": " << s.status().to_string();
  return s.ok() ? std::move(s).value() : GenSpec{};
}

// Expects INVALID_ARGUMENT whose message contains every fragment.
void expect_invalid(const Status& s, std::initializer_list<const char*> fragments) {
  EXPECT_EQ(s.code(), StatusCode::kInvalidArgument) << s.to_string();
  for (const char* f : fragments)
    EXPECT_NE(s.message().find(f), std::string::npos) << s.message() << " lacks " << f;
}

void expect_parse_error(const std::string& text, std::initializer_list<const char*> fragments) {
  SCOPED_TRACE(text);
  const auto s = parse_gen_spec(text);
  ASSERT_FALSE(s.ok());
  expect_invalid(s.status(), fragments);
}

TEST(GenSpec, PlainNameWithoutParameters) {
  const GenSpec s = parse_ok("gen:sphere");
  EXPECT_EQ(s.name, "sphere");
  EXPECT_EQ(s.text, "gen:sphere");
  EXPECT_TRUE(s.params.empty());
}

TEST(GenSpec, ParametersInOrder) {
  const GenSpec s = parse_ok("gen:sphere?level=2&radius=3.5&cx=-1e3");
  EXPECT_EQ(s.name, "sphere");
  ASSERT_EQ(s.params.size(), 3u);
  EXPECT_EQ(s.params[0].key, "level");
  EXPECT_EQ(s.params[0].value, "2");
  EXPECT_EQ(s.params[1].key, "radius");
  EXPECT_EQ(s.params[1].value, "3.5");
  EXPECT_EQ(s.params[2].key, "cx");
  EXPECT_EQ(s.params[2].value, "-1e3");
}

TEST(GenSpec, PercentEncodedValues) {
  const GenSpec s = parse_ok("gen:city?of=gen%3Asphere%3Flevel%3D2%26radius%3d3&copies=5");
  ASSERT_EQ(s.params.size(), 2u);
  EXPECT_EQ(s.params[0].value, "gen:sphere?level=2&radius=3");
  EXPECT_EQ(s.params[1].value, "5");
  EXPECT_EQ(parse_ok("gen:city?of=a%28b%29%25c+d.obj").params[0].value, "a(b)%c+d.obj");
  // '=' after the first one belongs to the value.
  EXPECT_EQ(parse_ok("gen:x?k=a=b").params[0].value, "a=b");
}

TEST(GenSpec, ParenthesisedValuesNestAndStayLiteral) {
  const GenSpec s = parse_ok("gen:city?of=(gen:sphere?level=2&radius=3)&copies=100");
  ASSERT_EQ(s.params.size(), 2u);
  EXPECT_EQ(s.params[0].key, "of");
  EXPECT_EQ(s.params[0].value, "gen:sphere?level=2&radius=3");
  EXPECT_EQ(s.params[1].key, "copies");
  EXPECT_EQ(s.params[1].value, "100");

  const GenSpec nested = parse_ok("gen:city?of=(gen:city?of=(gen:sphere?level=1&cx=2)&copies=2)&copies=3");
  ASSERT_EQ(nested.params.size(), 2u);
  EXPECT_EQ(nested.params[0].value, "gen:city?of=(gen:sphere?level=1&cx=2)&copies=2");
  const GenSpec inner = parse_ok(nested.params[0].value);
  EXPECT_EQ(inner.params[0].value, "gen:sphere?level=1&cx=2");
  EXPECT_EQ(parse_ok(inner.params[0].value).params.size(), 2u);

  // Not decoded inside parentheses: the nested spec decodes its own escapes.
  const GenSpec literal = parse_ok("gen:city?of=(gen:city?of=gen%3Asphere)");
  EXPECT_EQ(literal.params[0].value, "gen:city?of=gen%3Asphere");
  EXPECT_EQ(parse_ok(literal.params[0].value).params[0].value, "gen:sphere");
  // Parentheses are only special at the start of a value.
  EXPECT_EQ(parse_ok("gen:city?of=a(1).obj").params[0].value, "a(1).obj");
  EXPECT_EQ(parse_ok("gen:city?of=()").params[0].value, "");
}

TEST(GenSpec, SyntaxErrorsNameTheParameter) {
  expect_parse_error("sphere?level=1", {"gen:"});
  expect_parse_error("gen:", {"no generator name"});
  expect_parse_error("gen:?level=1", {"no generator name"});
  expect_parse_error("gen:sphere?", {"gen:sphere", "empty parameter list"});
  expect_parse_error("gen:sphere?level", {"gen:sphere", "'level'", "no value"});
  expect_parse_error("gen:sphere?level&radius=1", {"gen:sphere", "'level'", "no value"});
  expect_parse_error("gen:sphere?=3", {"gen:sphere", "empty parameter name"});
  expect_parse_error("gen:sphere?level=1&&radius=2", {"gen:sphere", "empty parameter name"});
  expect_parse_error("gen:sphere?level=1&", {"gen:sphere", "trailing '&'"});
  expect_parse_error("gen:sphere?radius=%2", {"gen:sphere", "'radius'", "percent"});
  expect_parse_error("gen:sphere?radius=%zz1", {"gen:sphere", "'radius'", "percent"});
  expect_parse_error("gen:city?of=(gen:sphere?level=1", {"gen:city", "'of'", "unbalanced"});
  expect_parse_error("gen:city?of=(a(b)", {"gen:city", "'of'", "unbalanced"});
  expect_parse_error("gen:city?of=(a)b&copies=1", {"gen:city", "'of'", "after ')'"});
}

TEST(GenSpec, DuplicateKeyIsAnError) {
  expect_parse_error("gen:sphere?level=1&radius=2&level=2", {"gen:sphere", "'level'", "twice"});
  // ... but the same key inside a nested spec is not a duplicate.
  parse_ok("gen:city?of=(gen:city?copies=2)&copies=3");
}

TEST(GenSpec, NameHelper) {
  EXPECT_EQ(gen_spec_name("gen:city?of=(gen:sphere)"), "city");
  EXPECT_EQ(gen_spec_name("gen:torus"), "torus");
  EXPECT_EQ(gen_spec_name("sphere.obj"), "");
}

struct Values {
  int level = 3;
  int64_t seed = 1;
  double radius = 1.0;
  std::optional<double> spacing;
  std::string of = "default";
};

Status read_values(const std::string& text, Values& v) {
  OUTCORE_ASSIGN_OR_RETURN(const GenSpec spec, parse_gen_spec(text));
  GenParams p(spec);
  p.integer("level", v.level, 0, 12);
  p.integer("seed", v.seed, 0, std::numeric_limits<int64_t>::max());
  p.real("radius", v.radius, RealRange::positive());
  p.real("spacing", v.spacing, RealRange::closed(0.5, 1.5));
  p.text("of", v.of);
  return p.finish();
}

TEST(GenParams, DefaultsAndTypedValues) {
  Values v;
  ASSERT_TRUE(read_values("gen:t", v).ok());
  EXPECT_EQ(v.level, 3);
  EXPECT_EQ(v.radius, 1.0);
  EXPECT_FALSE(v.spacing.has_value());
  EXPECT_EQ(v.of, "default");

  ASSERT_TRUE(
      read_values("gen:t?level=12&seed=9223372036854775807&radius=2.5e-3&spacing=1.5&of=x.obj", v).ok());
  EXPECT_EQ(v.level, 12);
  EXPECT_EQ(v.seed, std::numeric_limits<int64_t>::max());
  EXPECT_EQ(v.radius, 2.5e-3);
  EXPECT_EQ(v.spacing, 1.5);
  EXPECT_EQ(v.of, "x.obj");
}

TEST(GenParams, ErrorsNameGeneratorAndParameter) {
  const auto err = [](const std::string& text) {
    Values v;
    return read_values(text, v);
  };
  expect_invalid(err("gen:t?level=abc"), {"gen:t", "'level'", "'abc'", "not an integer"});
  expect_invalid(err("gen:t?level="), {"gen:t", "'level'", "not an integer"});
  expect_invalid(err("gen:t?level=2.0"), {"'level'", "not an integer"});
  expect_invalid(err("gen:t?level=+2"), {"'level'", "not an integer"});
  expect_invalid(err("gen:t?level=13"), {"gen:t", "'level'", "13", "out of range [0, 12]"});
  expect_invalid(err("gen:t?level=-1"), {"'level'", "out of range [0, 12]"});
  expect_invalid(err("gen:t?level=99999999999999999999999"), {"'level'", "out of range"});
  expect_invalid(err("gen:t?seed=-5"), {"'seed'", "out of range"});
  expect_invalid(err("gen:t?radius=0"), {"gen:t", "'radius'", "out of range (0, 1e+30]"});
  expect_invalid(err("gen:t?radius=-2"), {"'radius'", "out of range"});
  expect_invalid(err("gen:t?radius=nan"), {"'radius'", "out of range"});
  expect_invalid(err("gen:t?radius=inf"), {"'radius'", "out of range"});
  expect_invalid(err("gen:t?radius=1e999"), {"'radius'", "out of range"});
  expect_invalid(err("gen:t?radius=1x"), {"'radius'", "'1x'", "not a number"});
  expect_invalid(err("gen:t?spacing=2"), {"'spacing'", "out of range [0.5, 1.5]"});
  expect_invalid(err("gen:t?of="), {"'of'", "empty"});
  // Unknown: names it and lists the known parameters.
  expect_invalid(err("gen:t?lvl=3"),
                 {"gen:t", "unknown parameter 'lvl'", "known: level, seed, radius, spacing, of"});
  // The first error in declaration order wins over unknown parameters.
  expect_invalid(err("gen:t?lvl=3&radius=-1"), {"'radius'"});
}

TEST(GenParams, CustomFailure) {
  const GenSpec spec = parse_ok("gen:t?a=1");
  GenParams p(spec);
  int a = 0;
  p.integer("a", a, 0, 5);
  EXPECT_TRUE(p.has("a"));
  EXPECT_FALSE(p.has("b"));
  p.fail("a", "must be even");
  expect_invalid(p.finish(), {"gen:t: parameter 'a' must be even"});
}

TEST(GenParams, RangeText) {
  EXPECT_EQ(RealRange::positive().to_string(), "(0, 1e+30]");
  EXPECT_EQ(RealRange::any().to_string(), "[-1e+30, 1e+30]");
  EXPECT_EQ(RealRange::closed(0.5, 1.5).to_string(), "[0.5, 1.5]");
  EXPECT_TRUE(RealRange::positive().contains(1e-300));
  EXPECT_FALSE(RealRange::positive().contains(0.0));
}

}  // namespace OUTCORE_UNITY_ID
}  // namespace outcore
