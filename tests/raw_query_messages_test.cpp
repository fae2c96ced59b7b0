// The C++ client's copy-free bytes-path messages (client/cpp/raw_query_messages.h)
// against the generated protobuf classes, their reference: a request parses
// as the QueryRequest the typed API would send, and a reply cut into slices
// anywhere decodes to the generated response's fields and answers.
#include "client/cpp/raw_query_messages.h"

#include <google/protobuf/util/message_differencer.h>
#include <gtest/gtest.h>

#include <random>
#include <string>
#include <vector>

namespace outcore::client {
namespace OUTCORE_UNITY_ID {

std::string bytes_of(const grpc::ByteBuffer& buffer) {
  std::vector<grpc::Slice> slices;
  EXPECT_TRUE(buffer.Dump(&slices).ok());
  std::string bytes;
  for (const grpc::Slice& slice : slices)
    bytes.append(reinterpret_cast<const char*>(slice.begin()), slice.size());
  return bytes;
}

// `bytes` as a ByteBuffer of slices cut at random places (some empty).
RawQueryReply sliced(const std::string& bytes, std::mt19937& rng) {
  std::vector<grpc::Slice> slices;
  std::size_t at = 0;
  while (at < bytes.size()) {
    const std::size_t n = std::min<std::size_t>(bytes.size() - at, rng() % 40);
    slices.emplace_back(bytes.data() + at, n);
    at += n;
  }
  RawQueryReply reply;
  reply.buffer = grpc::ByteBuffer(slices.data(), slices.size());
  return reply;
}

TEST(RawQueryMessages, RequestParsesAsTheTypedRequest) {
  std::vector<Ray> rays(1000);
  for (std::size_t i = 0; i < rays.size(); ++i) {
    rays[i].origin = {float(i), 1, 2};
    rays[i].direction = {0, 0, 1};
    rays[i].tnear = 0.5f;
    rays[i].tfar = 100.f + float(i);
  }
  for (const bool strict : {false, true}) {
    for (const uint64_t sequence : {uint64_t{0}, uint64_t{1}, uint64_t{1} << 40}) {
      for (const auto fields : {v1::HIT_FIELDS_ALL, v1::HIT_FIELDS_T, v1::HIT_FIELDS_T_IDS}) {
        for (const std::size_t n : {std::size_t{0}, std::size_t{1}, rays.size()}) {
          QueryRequestFields asked;
          asked.strict = strict;
          asked.no_reorder = !strict;
          asked.sequence = sequence;
          asked.hit_fields = fields;
          // A replica's part (routing by brick), with ids of several varint bytes.
          const std::vector<uint32_t> part = {0, 7, 300, 70000, 4000000000u};
          if (strict) asked.only_bricks = part;
          const RawQueryRequest raw = encode_query_request(std::span<const Ray>(rays.data(), n), asked);
          v1::QueryRequest parsed;
          ASSERT_TRUE(parsed.ParseFromString(bytes_of(raw.buffer)));
          v1::QueryRequest expected;
          expected.mutable_batch()->set_layout_version(1);
          expected.mutable_batch()->set_ray_layout(v1::RAY_LAYOUT_F32X8);
          expected.mutable_batch()->set_ray_count(n);
          expected.mutable_batch()->set_rays(reinterpret_cast<const char*>(rays.data()), n * sizeof(Ray));
          expected.set_strict(strict);
          expected.set_no_reorder(!strict);
          expected.set_sequence(sequence);
          expected.set_hit_fields(fields);
          if (strict) expected.mutable_only_bricks()->Add(part.begin(), part.end());
          EXPECT_TRUE(google::protobuf::util::MessageDifferencer::Equals(parsed, expected))
              << parsed.ShortDebugString().substr(0, 300);
          // The rays are referenced, not copied: the same bytes.
          if (n > 0) {
            EXPECT_EQ(parsed.batch().rays(), expected.batch().rays());
          }
        }
      }
    }
  }
}

TEST(RawQueryMessages, ReplyCutAnywhereDecodesAsTheTypedReply) {
  std::mt19937 rng(29);
  v1::IntersectResponse response;
  response.set_layout_version(1);
  response.set_ray_count(100);
  std::string hits(100 * 32, '\0');
  for (std::size_t i = 0; i < hits.size(); ++i) hits[i] = static_cast<char>(rng());
  response.set_hits(hits);
  response.set_sequence(77);
  response.mutable_stats()->set_rays(100);
  response.mutable_stats()->set_brick_visits(1234);
  response.mutable_stats()->set_seconds_total(0.25);
  response.set_dynamic_version(5);
  response.set_hit_fields(v1::HIT_FIELDS_ALL);
  const std::string bytes = response.SerializeAsString();
  for (int trial = 0; trial < 50; ++trial) {
    std::vector<uint8_t> answers(hits.size(), 0);
    ReplyHeader header;
    ASSERT_TRUE(decode_query_reply(sliced(bytes, rng), answers, header).ok());
    EXPECT_EQ(header.layout_version, 1u);
    EXPECT_EQ(header.ray_count, 100u);
    EXPECT_EQ(header.sequence, 77u);
    EXPECT_EQ(header.dynamic_version, 5u);
    EXPECT_FALSE(header.answers_in_shared);
    EXPECT_EQ(header.answer_bytes, hits.size());
    EXPECT_EQ(std::string(answers.begin(), answers.end()), hits);
    EXPECT_TRUE(google::protobuf::util::MessageDifferencer::Equals(header.stats, response.stats()));
  }
  // Answers of another size are reported, not copied.
  std::vector<uint8_t> small(10, 7);
  ReplyHeader header;
  ASSERT_TRUE(decode_query_reply(sliced(bytes, rng), small, header).ok());
  EXPECT_EQ(header.answer_bytes, hits.size());
  EXPECT_EQ(small, std::vector<uint8_t>(10, 7));
}

TEST(RawQueryMessages, TruncatedOrBrokenRepliesAreDataLoss) {
  std::mt19937 rng(3);
  v1::OccludedResponse response;
  response.set_layout_version(1);
  response.set_ray_count(64);
  response.set_occluded(std::string(64, '\1'));
  response.mutable_stats()->set_rays(64);
  const std::string bytes = response.SerializeAsString();
  std::vector<uint8_t> answers(64);
  for (std::size_t cut = 1; cut < bytes.size(); ++cut) {
    ReplyHeader header;
    const Status status = decode_query_reply(sliced(bytes.substr(0, cut), rng), answers, header);
    // A cut between two fields parses (a shorter message); inside one it must not.
    if (!status.ok()) {
      EXPECT_EQ(status.code(), StatusCode::kDataLoss) << cut;
    }
  }
  ReplyHeader header;
  const Status group = decode_query_reply(sliced(std::string("\x0b\x01", 2), rng), answers, header);
  EXPECT_EQ(group.code(), StatusCode::kDataLoss);  // wire type 3 (groups) is refused
  EXPECT_NE(group.message().find("wire type 3"), std::string::npos);
}

}  // namespace OUTCORE_UNITY_ID
}  // namespace outcore::client
