// SharedMemoryObject: a POSIX shared-memory object (shm_open; on Linux a file
// in /dev/shm) mapped read-write, through which a client on the server's host
// hands over a batch's rays and receives its answers without copying them
// through gRPC and socket buffers (proto SharedPayload, docs/REMOTE_API.md).
//
// Every object starts with a header of kHeaderBytes: its first kTokenBytes are
// a random token the creator writes and sends along with the name, so that a
// process that merely learnt the name (anyone can list /dev/shm) cannot make
// the server read or write the object (check_token()). Payloads start at or
// after kHeaderBytes.
//
// The two sides do not trust each other's memory: the server never traces
// from the object, it copies the rays out and the answers in with
// copy_out()/copy_in(), which survive the object being truncated underneath
// them (the kernel then raises SIGBUS on the mapped pages; a guarded copy
// turns that into an error instead of a crash). The creator reserves the
// object's pages up front (posix_fallocate), so a full /dev/shm is an error at
// creation, not a SIGBUS at the first write.
//
// Thread-safety: open()/create() are reentrant. One object may be copied into
// and out of from several threads at once only on disjoint ranges; the SIGBUS
// guard is per thread.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>
#include <string_view>

#include "core/util/status.h"

namespace outcore {

// Which object a name stood for: it is the same object while these hold
// (its contents, and so its times, change with every call).
struct SharedObjectIdentity {
  uint64_t device = 0;
  uint64_t inode = 0;
  uint64_t size = 0;
  bool operator==(const SharedObjectIdentity&) const = default;
};

class SharedMemoryObject {
 public:
  // Names are "/outcore-" followed by 1..kMaxNameSuffix of [A-Za-z0-9_.-]:
  // no path, nothing another program's objects are likely to be called.
  static constexpr std::string_view kNamePrefix = "/outcore-";
  static constexpr std::size_t kMaxNameSuffix = 200;
  // The header: the token, then room up to a cache line.
  static constexpr std::size_t kTokenBytes = 16;
  static constexpr std::size_t kHeaderBytes = 64;

  SharedMemoryObject() = default;
  ~SharedMemoryObject();
  SharedMemoryObject(SharedMemoryObject&& other) noexcept;
  SharedMemoryObject& operator=(SharedMemoryObject&& other) noexcept;
  SharedMemoryObject(const SharedMemoryObject&) = delete;
  SharedMemoryObject& operator=(const SharedMemoryObject&) = delete;

  // INVALID_ARGUMENT naming what is wrong with `name`, else OK.
  static Status check_name(std::string_view name);

  // Opens an existing object (the server's side) and maps its first
  // min(map_bytes, size()) bytes, all pages at once: only what a call's
  // ranges need, however large the object. Never waits: the name is opened
  // non-blocking and without following links, and checked before use.
  // INVALID_ARGUMENT for a bad name and for anything but a regular file (a
  // FIFO, a symbolic link, a directory, ...), naming what it is; NOT_FOUND
  // when there is no such object; PERMISSION_DENIED for an object of another
  // user (or one this user may not open); IO_ERROR otherwise.
  static Expected<SharedMemoryObject> open(const std::string& name, std::size_t map_bytes = ~std::size_t{0});

  // The identity of the object `name` names now (open, fstat, close; no
  // mapping, no waiting). Errors as open()'s.
  static Expected<SharedObjectIdentity> identify(const std::string& name);

  // Creates a new object of `bytes` bytes (at least kHeaderBytes), named
  // kNamePrefix + `suffix` + a random tail, reserves its pages, maps it and
  // writes a fresh random token into its header (the client's side). The
  // object is unlinked when this is destroyed. RESOURCE_EXHAUSTED when
  // /dev/shm has no room; IO_ERROR otherwise.
  static Expected<SharedMemoryObject> create(std::string_view suffix, std::size_t bytes);

  // Unlinks the objects a client of kind `client` ("cpp", "py") left behind
  // when it died without closing them: names kNamePrefix + client + "-PID-..."
  // owned by this user whose PID is no longer running. Returns how many it
  // removed. Clients call it once per process before their first object.
  static int remove_orphans(std::string_view client);

  // PERMISSION_DENIED unless the header's token equals `token` (which must
  // be kTokenBytes long); FAILED_PRECONDITION when the object was truncated.
  Status check_token(std::string_view token) const;

  // Copies bytes [offset, offset + out_bytes) of the object into `out`, or
  // `in_bytes` bytes into the object at `offset`. OUT_OF_RANGE when the range
  // is not inside the mapping; FAILED_PRECONDITION when the object was
  // truncated (SIGBUS) during the copy. Either way nothing is left half
  // done that matters: the destination is the caller's to discard.
  Status copy_out(std::size_t offset, void* out, std::size_t out_bytes) const;
  Status copy_in(std::size_t offset, const void* in, std::size_t in_bytes);

  const std::string& name() const { return name_; }
  // What the object was when opened or created.
  const SharedObjectIdentity& identity() const { return identity_; }
  // True once no name refers to the object any more (its creator unlinked
  // it): an opened object keeps its descriptor to tell. Keeping such a
  // mapping keeps the object's memory allocated.
  bool unlinked() const;
  // The object's size when it was opened or created.
  std::size_t size() const { return size_; }
  // Bytes mapped from offset 0 (size() for the creator).
  std::size_t mapped_bytes() const { return mapped_; }
  // The creator's token (empty for an opened object).
  const std::string& token() const { return token_; }
  // The mapping, for the creator's own reads and writes (it trusts itself).
  char* data() { return data_; }
  const char* data() const { return data_; }

 private:
  SharedMemoryObject(std::string name, char* data, std::size_t size, std::size_t mapped, bool owner)
      : name_(std::move(name)), data_(data), size_(size), mapped_(mapped), owner_(owner) {}
  void release();

  std::string name_;
  std::string token_;
  SharedObjectIdentity identity_;
  int descriptor_ = -1;  // an opened object's, for unlinked()
  char* data_ = nullptr;
  std::size_t size_ = 0;
  std::size_t mapped_ = 0;
  bool owner_ = false;  // unlink on destruction
};

}  // namespace outcore
