"""Shared-memory segments for same-host shared payloads (proto SharedPayload).

Why: a client on the server's host otherwise pushes every ray and every hit
through protobuf framing, gRPC's buffers and the kernel's socket buffers, one
way and back. With a shared payload the rays are copied once into a POSIX
shared-memory object this process created, the server copies them out by name
(shm_open) and writes the answers back into the same object, and the client
copies those out: the messages carry only counts and stats.

A segment starts with a HEADER_BYTES header whose first TOKEN_BYTES are a
random token, sent with each call that names the segment: /dev/shm can be
listed by anyone, so the name alone must not let another process have the
server read or write the segment.

A segment is the file /dev/shm/outcore-py-<pid>-<16 random hex digits> (what
shm_open("/outcore-py-...") names on Linux), created O_EXCL with mode 0600,
its pages reserved with posix_fallocate (so a full /dev/shm, 64 MiB by default
in docker, is an OSError at creation instead of a SIGBUS at the first write),
then mapped. It is unlinked when closed, when garbage-collected, or at the
latest at interpreter exit (weakref.finalize), and only by the process that
created it (a forked child neither reuses nor removes its parent's segments).

SegmentPool keeps a few free segments for reuse across calls, so a steady
stream of batches costs no file creation; a batch that needs more than the
free segments hold replaces one of them with a larger segment.

Thread-safety: SegmentPool is thread-safe (one lock around its free list). A
Segment belongs to the single call that took it from the pool until that call
gives it back, so concurrent calls never share one. Segment itself is not
locked.
"""

from __future__ import annotations

import ipaddress
import mmap
import os
import secrets
import sys
import threading
import weakref

import numpy as np

SHM_DIR = "/dev/shm"
# The segment's header: a random token in its first TOKEN_BYTES, sent along
# with the call (the server compares the two); payloads start after it.
HEADER_BYTES = 64
TOKEN_BYTES = 16
# The clients' choice: the answers start on a cache line (the server only
# checks that ranges are inside the segment, after its header, and apart).
ALIGNMENT = 64
NAME_PREFIX = "outcore-py-"
# Smallest segment made: below it, growth steps would cost more than they save.
_MIN_SEGMENT_BYTES = 1 << 20
# Free segments kept for reuse; more concurrent calls than this make (and
# then drop) segments of their own.
KEEP_FREE = 4

# Copies into and out of a segment of at least this many bytes are split
# over threads (numpy releases the GIL while it copies plain bytes): a 1 M-ray
# batch is 24-32 MiB each way, several milliseconds on one core.
_PARALLEL_COPY_BYTES = 4 << 20
_copy_pool = None
_copy_pool_lock = threading.Lock()


def _copy_workers() -> int:
    return max(1, min(4, os.cpu_count() or 1))


def parallel_copy(dst: np.ndarray, src: np.ndarray) -> None:
    """np.copyto(dst, src) for 1-D uint8 arrays of one size, in parts on a
    small thread pool when large (the calling thread copies one part)."""
    global _copy_pool
    parts = _copy_workers()
    if src.size < _PARALLEL_COPY_BYTES or parts == 1:
        np.copyto(dst, src)
        return
    with _copy_pool_lock:
        if _copy_pool is None:
            from concurrent.futures import ThreadPoolExecutor
            _copy_pool = ThreadPoolExecutor(max_workers=parts - 1, thread_name_prefix="outcore-copy")
        pool = _copy_pool
    step = -(-src.size // parts)
    bounds = [(i * step, min(src.size, (i + 1) * step)) for i in range(parts)]
    futures = [pool.submit(np.copyto, dst[a:b], src[a:b]) for a, b in bounds[1:]]
    a, b = bounds[0]
    np.copyto(dst[a:b], src[a:b])
    for future in futures:
        future.result()


def supported() -> bool:
    """Whether this platform names shared-memory objects as files in /dev/shm."""
    return sys.platform.startswith("linux") and hasattr(os, "posix_fallocate")


def round_up(value: int, multiple: int) -> int:
    return -(-value // multiple) * multiple


def segment_size(need: int) -> int:
    """Bytes to allocate for a batch that needs `need`: rounded up to an
    eighth of the next power of two, and to whole MiB (spare below a quarter
    of `need` or 1 MiB, and few regrowths for slowly growing batches)."""
    granule = max(_MIN_SEGMENT_BYTES, 1 << max(0, need.bit_length() - 3))
    return max(_MIN_SEGMENT_BYTES, round_up(need, granule))


def new_segment_name() -> str:
    """A fresh object name, "/outcore-py-<pid>-<16 hex>" (the server accepts
    "/outcore-" followed by 1..200 of [A-Za-z0-9_.-])."""
    return f"/{NAME_PREFIX}{os.getpid()}-{secrets.token_hex(8)}"


def _remove_file(path: str, pid: int) -> None:
    if os.getpid() != pid:  # a forked child: the file is its parent's
        return
    try:
        os.unlink(path)
    except OSError:  # already gone (or /dev/shm cleaned by someone else)
        pass


_orphans_removed_in: int | None = None  # the pid that already removed orphans


def remove_orphans() -> int:
    """Unlinks segments that Python clients left behind when they died
    without closing them (outcore-py-PID-... of this user whose PID is not
    running); the same rule as SharedMemoryObject::remove_orphans for the C++
    client. Returns how many it removed."""
    removed = 0
    prefix = NAME_PREFIX
    try:
        names = os.listdir(SHM_DIR)
    except OSError:
        return 0
    for name in names:
        if not name.startswith(prefix):
            continue
        pid_text, dash, _ = name[len(prefix):].partition("-")
        if not dash or not pid_text.isdigit() or not 0 < len(pid_text) <= 9:
            continue
        try:
            os.kill(int(pid_text), 0)
            continue  # alive
        except ProcessLookupError:
            pass
        except OSError:
            continue  # someone else's process: alive
        path = os.path.join(SHM_DIR, name)
        try:
            info = os.lstat(path)
            if info.st_uid == os.geteuid() and (info.st_mode & 0o170000) == 0o100000:
                os.unlink(path)
                removed += 1
        except OSError:
            pass
    return removed


class Segment:
    """One mapped shared-memory object of `size` bytes, named `name`."""

    __slots__ = ("name", "path", "size", "token", "_map", "_remove", "__weakref__")

    def __init__(self, size: int):
        """Creates the object; OSError (and no file left behind) when it
        cannot be made: no /dev/shm, no room in it, a mapping refused..."""
        if size < HEADER_BYTES:
            raise ValueError(f"segment size must be at least {HEADER_BYTES}, got {size}")
        global _orphans_removed_in
        if _orphans_removed_in != os.getpid():
            _orphans_removed_in = os.getpid()
            remove_orphans()
        self.name = new_segment_name()
        self.path = os.path.join(SHM_DIR, self.name[1:])
        self.size = size
        fd = os.open(self.path, os.O_RDWR | os.O_CREAT | os.O_EXCL | os.O_CLOEXEC, 0o600)
        try:
            # Registered before anything else can fail, so the file goes even
            # if this process dies between here and close().
            self._remove = weakref.finalize(self, _remove_file, self.path, os.getpid())
            try:
                os.posix_fallocate(fd, 0, size)
                self._map = mmap.mmap(fd, size)  # MAP_SHARED, read-write
                self.token = secrets.token_bytes(TOKEN_BYTES)
                self._map[:TOKEN_BYTES] = self.token
            except BaseException:
                self._remove()
                raise
        finally:
            os.close(fd)  # the mapping keeps the object

    def write_rays(self, rays: np.ndarray, offset: int = HEADER_BYTES) -> None:
        """Copies C-contiguous '<f4' (n, 6|8) rays to `offset` (one copy)."""
        src = rays.reshape(-1).view(np.uint8)
        dst = np.frombuffer(self._map, dtype=np.uint8, count=src.size, offset=offset)
        parallel_copy(dst, src)
        # dst dies here: no export of the mapping outlives the call, so
        # close() can always unmap.

    def read_answers(self, dtype: np.dtype, count: int, offset: int) -> np.ndarray:
        """A read-only COPY of `count` records of `dtype` at `offset`: results
        never alias the segment, which the next call reuses."""
        # Copied as raw bytes, then viewed as records: numpy copies a
        # structured dtype with a subarray field record by record (50-100 ms
        # for 1 M hits against 8 ms for the bytes).
        dtype = np.dtype(dtype)
        raw = np.frombuffer(self._map, dtype=np.uint8, count=count * dtype.itemsize, offset=offset)
        out = np.empty(raw.size, dtype=np.uint8)
        parallel_copy(out, raw)
        out = out.view(dtype)
        del raw  # no export of the mapping outlives the call
        out.flags.writeable = False
        return out

    def close(self) -> None:
        """Unlinks the file and unmaps (idempotent)."""
        self._remove()
        try:
            self._map.close()
        except BufferError:  # a view still exists: the mapping goes with it
            pass

    def __repr__(self) -> str:
        return f"Segment({self.name!r}, size={self.size})"


class SegmentPool:
    """Segments for concurrent calls: take() one of at least `need` bytes,
    give() it back after the call. Closing unlinks every free segment now and
    every segment still in use when it is given back."""

    def __init__(self, keep: int = KEEP_FREE):
        self._lock = threading.Lock()
        self._free: list[Segment] = []
        self._keep = keep
        self._closed = False
        self._pid = os.getpid()

    def take(self, need: int) -> Segment:
        """A free segment of >= need bytes, or a new one (OSError when it
        cannot be made, or when the pool is closed)."""
        too_small = None
        with self._lock:
            if self._closed:
                raise OSError("the shared-memory segment pool is closed")
            if self._pid != os.getpid():
                # Forked: the inherited segments are the parent's (it keeps
                # using and finally unlinks them); forget them.
                self._free = []
                self._pid = os.getpid()
            fitting = [s for s in self._free if s.size >= need]
            if fitting:
                segment = min(fitting, key=lambda s: s.size)
                self._free.remove(segment)
                return segment
            if self._free:  # all too small: grow by replacing the largest
                too_small = max(self._free, key=lambda s: s.size)
                self._free.remove(too_small)
        if too_small is not None:
            too_small.close()
        # Outside the lock: reserving many MiB takes a while.
        return Segment(segment_size(need))

    def give(self, segment: Segment, reusable: bool = True) -> None:
        """Returns a segment taken from this pool. reusable=False (the call
        failed, so the server may still write into it) closes it instead."""
        with self._lock:
            if reusable and not self._closed and self._pid == os.getpid() and len(self._free) < self._keep:
                self._free.append(segment)
                return
        segment.close()

    def close(self) -> None:
        with self._lock:
            self._closed = True
            free, self._free = self._free, []
        for segment in free:
            segment.close()


def _host_of(hostport: str) -> str:
    if hostport.startswith("["):  # [v6]:port
        end = hostport.find("]")
        return hostport[1:end] if end > 0 else ""
    if hostport.count(":") == 1:  # host:port
        return hostport.split(":", 1)[0]
    return hostport  # host without a port, or a bare IPv6 address


def _is_loopback_host(host: str) -> bool:
    if host.lower().rstrip(".") == "localhost":
        return True
    try:
        address = ipaddress.ip_address(host)
    except ValueError:
        return False
    if isinstance(address, ipaddress.IPv6Address) and address.ipv4_mapped is not None:
        address = address.ipv4_mapped
    return address.is_loopback


def is_loopback_target(target: str) -> bool:
    """Whether a gRPC target names this host: "localhost:port",
    "127.x.y.z:port", "[::1]:port", "::1", "ipv4:127...", "ipv6:[::1]...",
    "dns:" forms of those, or a "unix:"/"unix-abstract:" socket. Only a hint:
    the server decides from the peer address it sees."""
    if target.startswith(("unix:", "unix-abstract:")):
        return True
    if target.startswith(("ipv4:", "ipv6:")):
        addresses = target[5:].split(",")
        return all(_is_loopback_host(_host_of(a)) for a in addresses)
    if target.startswith("dns:"):
        target = target[4:]
        if target.startswith("//"):  # dns://authority/host:port
            _, _, target = target[2:].partition("/")
    return _is_loopback_host(_host_of(target))
