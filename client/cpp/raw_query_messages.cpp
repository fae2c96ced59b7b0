#include "client/cpp/raw_query_messages.h"

#include <grpcpp/support/slice.h>

#include <algorithm>
#include <cstring>
#include <vector>

namespace outcore::client {

namespace {

enum WireType : uint32_t { kVarint = 0, kFixed64 = 1, kLength = 2, kFixed32 = 5 };

void put_varint(std::string& out, uint64_t value) {
  while (value >= 0x80) {
    out.push_back(static_cast<char>((value & 0x7F) | 0x80));
    value >>= 7;
  }
  out.push_back(static_cast<char>(value));
}

void put_tag(std::string& out, uint32_t field, WireType type) {
  put_varint(out, field << 3 | type);
}

// Reads bytes across a reply's slices in order.
class SliceReader {
 public:
  explicit SliceReader(const std::vector<grpc::Slice>& slices) : slices_(slices) { skip_empty(); }

  bool done() const { return slice_ == slices_.size(); }

  bool read_byte(uint8_t& byte) {
    if (done()) return false;
    byte = slices_[slice_].begin()[at_];
    advance(1);
    return true;
  }
  bool read_varint(uint64_t& value) {
    value = 0;
    for (int shift = 0; shift < 64; shift += 7) {
      uint8_t byte;
      if (!read_byte(byte)) return false;
      value |= uint64_t{byte & 0x7Fu} << shift;
      if ((byte & 0x80) == 0) return true;
    }
    return false;
  }
  // Copies `n` bytes to `out` (null: skips them).
  bool read(uint8_t* out, uint64_t n) {
    while (n > 0) {
      if (done()) return false;
      const std::size_t available = slices_[slice_].size() - at_;
      const std::size_t take = static_cast<std::size_t>(std::min<uint64_t>(n, available));
      if (out != nullptr) {
        std::memcpy(out, slices_[slice_].begin() + at_, take);
        out += take;
      }
      n -= take;
      advance(take);
    }
    return true;
  }

 private:
  void advance(std::size_t n) {
    at_ += n;
    if (at_ == slices_[slice_].size()) {
      ++slice_;
      at_ = 0;
      skip_empty();
    }
  }
  void skip_empty() {
    while (slice_ < slices_.size() && slices_[slice_].size() == 0) ++slice_;
  }

  const std::vector<grpc::Slice>& slices_;
  std::size_t slice_ = 0;
  std::size_t at_ = 0;
};

Status malformed(const std::string& what) {
  return data_loss("the server's reply does not parse: " + what);
}

}  // namespace

RawQueryRequest encode_query_request(std::span<const Ray> rays, const QueryRequestFields& fields) {
  const uint64_t ray_bytes = rays.size_bytes();
  // RayBatch: layout_version 1, F32X8, ray_count, then the rays' tag and length.
  std::string batch;
  put_tag(batch, 1, kVarint);
  put_varint(batch, 1);
  put_tag(batch, 2, kVarint);
  put_varint(batch, v1::RAY_LAYOUT_F32X8);
  if (!rays.empty()) {
    put_tag(batch, 3, kVarint);
    put_varint(batch, rays.size());
    put_tag(batch, 4, kLength);
    put_varint(batch, ray_bytes);
  }
  std::string head;
  put_tag(head, 1, kLength);
  put_varint(head, batch.size() + (rays.empty() ? 0 : ray_bytes));
  head += batch;
  std::string tail;
  if (fields.strict) {
    put_tag(tail, 2, kVarint);
    put_varint(tail, 1);
  }
  if (fields.no_reorder) {
    put_tag(tail, 3, kVarint);
    put_varint(tail, 1);
  }
  if (fields.sequence != 0) {
    put_tag(tail, 4, kVarint);
    put_varint(tail, fields.sequence);
  }
  if (fields.hit_fields != v1::HIT_FIELDS_ALL) {
    put_tag(tail, 7, kVarint);
    put_varint(tail, static_cast<uint64_t>(fields.hit_fields));
  }
  if (!fields.only_bricks.empty()) {
    std::string packed;
    for (const uint32_t brick : fields.only_bricks) put_varint(packed, brick);
    put_tag(tail, 8, kLength);
    put_varint(tail, packed.size());
    tail += packed;
  }
  std::vector<grpc::Slice> slices;
  slices.emplace_back(head);
  if (!rays.empty()) slices.emplace_back(rays.data(), ray_bytes, grpc::Slice::STATIC_SLICE);
  if (!tail.empty()) slices.emplace_back(tail);
  RawQueryRequest request;
  request.buffer = grpc::ByteBuffer(slices.data(), slices.size());
  return request;
}

Status decode_query_reply(const RawQueryReply& reply, std::span<uint8_t> answers, ReplyHeader& header) {
  header = ReplyHeader{};
  std::vector<grpc::Slice> slices;
  if (reply.buffer.Valid() && !reply.buffer.Dump(&slices).ok()) return malformed("unreadable buffer");
  SliceReader in(slices);
  std::string stats;
  while (!in.done()) {
    uint64_t key;
    if (!in.read_varint(key)) return malformed("truncated field key");
    const uint64_t field = key >> 3;
    const auto type = static_cast<uint32_t>(key & 7);
    if (type == kVarint) {
      uint64_t value;
      if (!in.read_varint(value)) return malformed("truncated varint of field " + std::to_string(field));
      if (field == 1) header.layout_version = static_cast<uint32_t>(value);
      if (field == 2) header.ray_count = value;
      if (field == 4) header.sequence = value;
      if (field == 6) header.answers_in_shared = value != 0;
      if (field == 7) header.dynamic_version = value;
    } else if (type == kLength) {
      uint64_t size;
      if (!in.read_varint(size)) return malformed("truncated length of field " + std::to_string(field));
      if (field == 3) {
        header.answer_bytes = size;
        const bool fits = size == answers.size();
        if (!in.read(fits ? answers.data() : nullptr, size)) return malformed("truncated answers");
      } else if (field == 5) {
        stats.resize(size);
        if (!in.read(reinterpret_cast<uint8_t*>(stats.data()), size)) return malformed("truncated stats");
      } else if (!in.read(nullptr, size)) {
        return malformed("truncated field " + std::to_string(field));
      }
    } else if (type == kFixed64 || type == kFixed32) {
      if (!in.read(nullptr, type == kFixed64 ? 8 : 4))
        return malformed("truncated field " + std::to_string(field));
    } else {
      return malformed("field " + std::to_string(field) + " has wire type " + std::to_string(type));
    }
  }
  if (!stats.empty() && !header.stats.ParseFromString(stats)) return malformed("the stats do not parse");
  return Status::Ok();
}

}  // namespace outcore::client
