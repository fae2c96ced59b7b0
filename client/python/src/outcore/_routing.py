"""Cache-affinity routing over replicas (issue 30): every replica serves the
whole scene from the same store, so any replica answers any ray the same;
having each brick traced on one replica makes the replicas' caches add up
instead of each holding the whole working set (docs/SCALING.md).

By brick (routing="bricks", the default): the bricks (SceneInfo.bricks) are
placed on the ring by the Morton code of their centres (brick_positions),
each replica 64 points, and shared out with bounded load 1.01 over their
triangles (plan_bricks); every replica gets the whole batch with its part
as QueryRequest.only_bricks, and the answers are merged ray by ray under
the engine's tie rule (merge_nearest). A part whose replica fails goes to
the next replica on the ring.

By ray (routing="rays"):

- The key of a ray is the cell of a grid over the scene's box (SceneInfo
  bounds) where the ray enters the box: `cells` (8) along the box's longest
  side, the other sides in proportion (a flat city gets 8 x 1 x 8), so that
  rays entering one column from above or below share a key. The key is the
  cell's Morton code scaled onto the 64-bit ring: neighbouring cells are
  neighbours on the ring. Rays that miss the box cost nothing anywhere; they
  get hashed positions by blocks of their index, so that they spread.
- Each replica is a few points (4 virtual nodes; FNV-1a + SplitMix64 of
  `address#i`, as the C++ client) on that ring, so it owns a
  few arcs of the Morton curve: compact regions of the scene, whose bricks
  its cache then holds. Keys go to the first replica clockwise whose rays
  stay within load_factor x the average (1.25; bounded load, Mirrokni,
  Thorup, Zadimoghaddam 2018): a replica over its share spills to the next
  arc, a neighbouring region, and a replica joining or leaving moves few
  keys.
- The parts go out in parallel and the answers are put back in input order.
  A part whose replica fails (UNAVAILABLE) goes again to the next replicas on
  the ring; the failed replica is left out until it has been down for
  retry_after seconds.
- Replicas come from a list, or from a "dns:///NAME:PORT" target resolved
  with getaddrinfo (a Kubernetes headless Service), resolved again when the
  last resolution is older than resolve_every seconds.

Thread-safety: a Router may be used from several threads; its replica set
is swapped under a lock.
"""

from __future__ import annotations

import math
import socket
import threading
import time
from concurrent.futures import ThreadPoolExecutor

import numpy as np

from .errors import OutcoreError

VIRTUAL_NODES = 4
# Routing by brick: more points a replica, so that each owns close to an even
# share of the ring and one joining takes close to 1/(N+1) of the bricks
# (measured on 81 bricks: 0.25 of the triangles move from 4 to 5 replicas
# with 64 points, 0.29 with 16, 0.31-0.37 with 4).
BRICK_VIRTUAL_NODES = 64
BRICK_LOAD_FACTOR = 1.01
MISS_BLOCK_RAYS = 8192


_MASK64 = (1 << 64) - 1


def _hash64(text: str) -> int:
    """FNV-1a over the UTF-8 bytes, then the SplitMix64 finaliser: the same
    64-bit value as the C++ client's ring_hash (client/cpp/replica_ring.cpp),
    so both clients place replicas and keys alike."""
    h = 0xCBF29CE484222325
    for byte in text.encode():
        h = ((h ^ byte) * 0x100000001B3) & _MASK64
    h = ((h ^ (h >> 30)) * 0xBF58476D1CE4E5B9) & _MASK64
    h = ((h ^ (h >> 27)) * 0x94D049BB133111EB) & _MASK64
    return h ^ (h >> 31)


class HashRing:
    """Replicas (address strings) on a 64-bit ring of virtual nodes; keys are
    positions on the ring (ray_keys)."""

    def __init__(self, replicas, virtual_nodes: int = VIRTUAL_NODES):
        self.replicas = sorted(set(replicas))
        points = sorted((_hash64(f"{r}#{i}"), r) for r in self.replicas for i in range(virtual_nodes))
        self._hashes = np.array([h for h, _ in points], dtype=np.uint64)
        self._owners = [r for _, r in points]

    def walk(self, position: int) -> list[str]:
        """Every replica once, in ring order from `position`."""
        if not self.replicas:
            return []
        start = int(np.searchsorted(self._hashes, np.uint64(position))) % len(self._owners)
        order, seen = [], set()
        for i in range(len(self._owners)):
            owner = self._owners[(start + i) % len(self._owners)]
            if owner not in seen:
                seen.add(owner)
                order.append(owner)
                if len(order) == len(self.replicas):
                    break
        return order

    def assign(self, counts: dict, load_factor: float = 1.25) -> dict:
        """key -> replica for keys (ring positions) with ray counts: each key
        to the first replica on its walk whose load stays within load_factor
        x the average (a key larger than that goes to the least loaded one)."""
        if not self.replicas:
            return {}
        total = sum(counts.values())
        capacity = math.ceil(load_factor * total / len(self.replicas))
        load = dict.fromkeys(self.replicas, 0)
        owner = {}
        # Large keys first, so the small ones fill the gaps they leave.
        for key in sorted(counts, key=lambda k: (-counts[k], k)):
            walk = self.walk(key)
            chosen = next((r for r in walk if load[r] + counts[key] <= capacity), None)
            if chosen is None:
                chosen = min(walk, key=lambda r: load[r])
            owner[key] = chosen
            load[chosen] += counts[key]
        return owner


def _spread_bits(v: np.ndarray) -> np.ndarray:
    """Bits of v (< 2**21) moved to every third position (Morton order)."""
    v = v.astype(np.uint64) & np.uint64(0x1FFFFF)
    for shift, mask in ((32, 0x1F00000000FFFF), (16, 0x1F0000FF0000FF), (8, 0x100F00F00F00F00F),
                        (4, 0x10C30C30C30C30C3), (2, 0x1249249249249249)):
        v = (v | (v << np.uint64(shift))) & np.uint64(mask)
    return v


def grid_dims(lo, hi, cells: int) -> np.ndarray:
    """Cells along each axis: `cells` along the box's longest side, the others
    in proportion (at least 1), so a flat scene gets a flat grid."""
    extent = np.maximum(np.asarray(hi, np.float64) - np.asarray(lo, np.float64), 0)
    longest = extent.max() if extent.max() > 0 else 1.0
    return np.maximum(1, np.floor(cells * extent / longest + 0.5)).astype(np.int64)


def ray_keys(rays: np.ndarray, lo, hi, cells: int = 8) -> np.ndarray:
    """The routing key of each (n, 6|8) ray, a position on the 64-bit ring:
    the Morton code of the grid cell where the ray enters the scene's box
    (grid_dims), scaled to the ring, so that neighbouring cells are
    neighbours on the ring and a replica's arcs are compact regions; rays
    that miss the box get hashed positions, by blocks of their index."""
    n = rays.shape[0]
    lo = np.asarray(lo, dtype=np.float64)
    hi = np.asarray(hi, dtype=np.float64)
    o = rays[:, 0:3].astype(np.float64)
    d = rays[:, 3:6].astype(np.float64)
    tnear = rays[:, 6].astype(np.float64) if rays.shape[1] == 8 else np.zeros(n)
    tfar = rays[:, 7].astype(np.float64) if rays.shape[1] == 8 else np.full(n, np.inf)
    with np.errstate(divide="ignore", invalid="ignore"):
        t0 = (lo - o) / d
        t1 = (hi - o) / d
    t_enter = np.fmax(np.nanmax(np.fmin(t0, t1), axis=1), tnear)
    t_exit = np.fmin(np.nanmin(np.fmax(t0, t1), axis=1), tfar)
    enters = np.isfinite(t_enter) & (t_enter <= t_exit)
    dims = grid_dims(lo, hi, cells)
    extent = np.where(hi > lo, hi - lo, 1.0)
    point = o + np.where(enters, t_enter, 0.0)[:, None] * d
    cell = np.clip(np.floor((point - lo) / extent * dims), 0, dims - 1)
    cell = np.nan_to_num(cell, nan=0.0).astype(np.int64)
    code = _spread_bits(cell[:, 0]) | (_spread_bits(cell[:, 1]) << np.uint64(1)) | \
        (_spread_bits(cell[:, 2]) << np.uint64(2))
    most = int(dims.max())
    bits = 3 * (max(1, int(np.ceil(np.log2(most)))) if most > 1 else 1)
    # Each cell's code at the middle of its slice of the ring.
    positions = (code << np.uint64(64 - bits)) + (np.uint64(1) << np.uint64(63 - bits))
    blocks = np.arange(n, dtype=np.int64) // MISS_BLOCK_RAYS
    miss_positions = np.array([_hash64(f"miss:{b}") for b in range(int(blocks[-1]) + 1 if n else 0)],
                              dtype=np.uint64)
    return np.where(enters, positions, miss_positions[blocks] if n else positions)


def brick_positions(bricks: list, lo, hi) -> np.ndarray:
    """Each brick's place on the ring (routing="bricks"): the Morton code of
    its box's centre on a 128^3 grid over the scene's box, so that a
    replica's arcs hold neighbouring bricks, with the brick id's hash below
    it so that no two bricks share a place."""
    if not bricks:
        return np.zeros(0, dtype=np.uint64)
    lo = np.asarray(lo, dtype=np.float64)
    extent = np.where(np.asarray(hi, np.float64) > lo, np.asarray(hi, np.float64) - lo, 1.0)
    centres = np.array([(np.asarray(b["bounds_lo"], np.float64) + np.asarray(b["bounds_hi"], np.float64)) / 2
                        for b in bricks])
    cell = np.clip(np.floor((centres - lo) / extent * 128), 0, 127).astype(np.int64)
    code = _spread_bits(cell[:, 0]) | (_spread_bits(cell[:, 1]) << np.uint64(1)) | \
        (_spread_bits(cell[:, 2]) << np.uint64(2))
    low = np.array([_hash64(f"brick:{i}") >> 21 for i in range(len(bricks))], dtype=np.uint64)
    return (code << np.uint64(43)) | low


def merge_nearest(merged: np.ndarray, part: np.ndarray) -> None:
    """Keeps in `merged` the nearer of its hit and the part's, ray by ray,
    under the engine's tie rule (smaller t, then geometry_id, then
    primitive_id; misses have t = inf): occlusion flags are ORed."""
    if merged.dtype.names is None:
        np.bitwise_or(merged, part, out=merged)
        return
    better = part["t_hit"] < merged["t_hit"]
    if "geometry_id" in merged.dtype.names:
        same_t = part["t_hit"] == merged["t_hit"]
        g, mg = part["geometry_id"], merged["geometry_id"]
        better |= same_t & ((g < mg) | ((g == mg) & (part["primitive_id"] < merged["primitive_id"])))
    merged[better] = part[better]


def combined_stats(parts: list, routing: str, merged: np.ndarray) -> dict:
    """The batch's figures from its parts' (dicts or None): sums of the work;
    routed by brick, every replica saw every ray, so rays and invalid_rays
    are one part's and rays_hit is counted in the merged answers."""
    totals: dict = {}
    for stats in parts:
        for key, value in (stats or {}).items():
            if isinstance(value, (int, float)) and not isinstance(value, bool):
                totals[key] = totals.get(key, 0) + value
    if routing == "bricks" and parts and parts[0]:
        for key in ("rays", "invalid_rays"):
            if key in parts[0]:
                totals[key] = parts[0][key]
        hit = np.isfinite(merged["t_hit"]) if merged.dtype.names else merged != 0
        totals["rays_hit"] = int(np.count_nonzero(hit))
    return totals


def resolve(target: str) -> list[str]:
    """HOST:PORT addresses a "dns:///NAME:PORT" (or "dns:NAME:PORT") target
    names now; OutcoreError UNAVAILABLE when it resolves to nothing."""
    name = target.split("dns:", 1)[1].lstrip("/")
    host, _, port = name.rpartition(":")
    host = host.strip("[]")
    try:
        infos = socket.getaddrinfo(host, int(port), type=socket.SOCK_STREAM)
    except (socket.gaierror, ValueError) as e:
        raise OutcoreError("UNAVAILABLE", f"cannot resolve {target}: {e}") from None
    addresses = []
    for family, _, _, _, sockaddr in infos:
        ip = sockaddr[0]
        address = f"[{ip}]:{port}" if family == socket.AF_INET6 else f"{ip}:{port}"
        if address not in addresses:
            addresses.append(address)
    if not addresses:
        raise OutcoreError("UNAVAILABLE", f"{target} resolves to no address")
    return sorted(addresses)


class Router:
    """Routes the ray queries of a replicated SceneClient (see the module)."""

    def __init__(self, targets, make_client, cells: int = 8, load_factor: float | None = None,
                 resolve_every: float = 30.0, retry_after: float = 30.0, routing: str = "bricks"):
        self._targets = list(targets)
        self._make_client = make_client
        self.routing = routing
        self._bricks = None  # SceneInfo.bricks, fetched once
        self._brick_plan = None  # (live replicas, their parts): made again when the live set changes
        self.cells = cells
        # Of an even share: of the triangles (bricks), of the rays (rays).
        self.load_factor = load_factor if load_factor is not None else (
            BRICK_LOAD_FACTOR if routing == "bricks" else 1.25)
        self.resolve_every = resolve_every
        self.retry_after = retry_after
        self._lock = threading.Lock()
        self._clients: dict[str, object] = {}
        self._down: dict[str, float] = {}  # replica -> when it failed
        self._resolved_at = -math.inf
        self._bounds = None
        #: Parts sent again to another replica after theirs failed.
        self.failovers = 0
        self._pool = ThreadPoolExecutor(max_workers=16, thread_name_prefix="outcore-route")
        self._refresh(force=True)

    # -- the replica set ----------------------------------------------------

    def _addresses(self) -> list[str]:
        addresses = []
        for target in self._targets:
            for address in (resolve(target) if target.startswith("dns:") else [target]):
                if address not in addresses:
                    addresses.append(address)
        return addresses

    def _refresh(self, force: bool = False) -> None:
        now = time.monotonic()
        if not force and now - self._resolved_at < self.resolve_every:
            return
        addresses = self._addresses()
        with self._lock:
            for gone in set(self._clients) - set(addresses):
                self._clients.pop(gone).close()
            for address in addresses:
                if address not in self._clients:
                    self._clients[address] = self._make_client(address)
            self._resolved_at = now

    def replicas(self) -> list[str]:
        with self._lock:
            return sorted(self._clients)

    def client(self, address: str):
        with self._lock:
            return self._clients[address]

    def _live(self) -> list[str]:
        now = time.monotonic()
        with self._lock:
            for address, when in list(self._down.items()):
                if now - when >= self.retry_after:
                    del self._down[address]
            return sorted(a for a in self._clients if a not in self._down)

    def _mark_down(self, address: str) -> None:
        with self._lock:
            self._down[address] = time.monotonic()

    def close(self) -> None:
        self._pool.shutdown(wait=True)
        with self._lock:
            for client in self._clients.values():
                client.close()
            self._clients.clear()

    # -- routing --------------------------------------------------------------

    def plan(self, rays: np.ndarray) -> tuple[HashRing, np.ndarray, list[str]]:
        """The ring over the live replicas, each ray's replica index, and the
        replicas by index."""
        live = self._live_with_scene()
        ring = HashRing(live)
        keys = ray_keys(rays, *self._bounds, cells=self.cells)
        unique, inverse, counts = np.unique(keys, return_inverse=True, return_counts=True)
        inverse = inverse.reshape(-1)
        owner = ring.assign({int(k): int(c) for k, c in zip(unique, counts)}, self.load_factor)
        index = {address: i for i, address in enumerate(ring.replicas)}
        replica_of_key = np.array([index[owner[int(k)]] for k in unique], dtype=np.int64)
        return ring, replica_of_key[inverse], ring.replicas

    def _live_with_scene(self) -> list[str]:
        """The replicas up, the scene's box (and bricks) known."""
        self._refresh()
        live = self._live()
        if not live:
            raise OutcoreError("UNAVAILABLE", "no replica is up (all failed in the last "
                                              f"{self.retry_after:g} s)")
        if self._bounds is None:
            self._bounds = self._scene_bounds(live)
            live = self._live()
        return live

    def _scene_bounds(self, live: list[str]):
        """The scene's box from the first replica that answers (and its
        bricks, for routing by bricks)."""
        for address in live:
            try:
                info = self.client(address).scene_info()
                self._bricks = info.get("bricks", [])
                return info["bounds_lo"], info["bounds_hi"]
            except OutcoreError as e:
                if e.code != "UNAVAILABLE":
                    raise
                self._mark_down(address)
        raise OutcoreError("UNAVAILABLE", f"no replica answered GetSceneInfo (tried {', '.join(live)})")

    def plan_bricks(self) -> dict:
        """Replica -> the brick ids it owns: bricks on the ring by place
        (brick_positions), weighed by their triangles, bounded load
        load_factor (1.01: parts within 1 % of an even share, so that a part
        fits a replica's share of the cache). Made once per set of live
        replicas (a batch reuses its predecessor's)."""
        live = tuple(self._live_with_scene())
        with self._lock:
            if self._brick_plan is not None and self._brick_plan[0] == live:
                return self._brick_plan[1]
        ring = HashRing(live, BRICK_VIRTUAL_NODES)
        positions = brick_positions(self._bricks, *self._bounds)
        weights = {int(p): max(1, int(b.get("triangle_count", 0))) for p, b in zip(positions, self._bricks)}
        owner = ring.assign(weights, self.load_factor)
        parts: dict = {}
        for brick, position in enumerate(positions):
            parts.setdefault(owner[int(position)], []).append(brick)
        with self._lock:
            self._brick_plan = (live, parts)
        return parts

    def query(self, rays: np.ndarray, run_part, out: np.ndarray) -> tuple[list, str]:
        """Answers `rays` into `out` by parts, run_part(client, part_rays,
        only_bricks) returning (answers, stats) per part; returns the parts'
        stats and how the batch was routed. routing="bricks": every replica
        traces every ray in its own bricks and the answers are merged
        (merge_nearest); "rays": each ray goes to one replica, by its key;
        also when the replicas list no bricks (servers from before
        SceneInfo.bricks)."""
        if self.routing == "bricks":
            parts = self.plan_bricks()
            if parts:
                return self._query_by_bricks(parts, rays, run_part, out), "bricks"
        ring, replica_of_ray, replicas = self.plan(rays)
        parts = [(replicas[r], np.flatnonzero(replica_of_ray == r)) for r in range(len(replicas))]
        parts = [(address, idx) for address, idx in parts if idx.size]
        futures = [(address, idx, self._pool.submit(run_part, self.client(address), rays[idx], ()))
                   for address, idx in parts]
        stats = []
        for address, idx, future in futures:
            answers, part_stats = self._finish_part(address, future, idx.size,
                                                    lambda client, idx=idx: run_part(client, rays[idx], ()))
            out[idx] = answers
            stats.append(part_stats)
        return stats, "rays"

    def _query_by_bricks(self, parts: dict, rays: np.ndarray, run_part, out: np.ndarray) -> list:
        # A replica that owns every brick (the only one up) traces the whole
        # scene: no part, so the engine may use its every-brick strategies.
        parts = {address: (() if len(bricks) == len(self._bricks) else tuple(bricks))
                 for address, bricks in parts.items()}
        futures = [(address, bricks, self._pool.submit(run_part, self.client(address), rays, bricks))
                   for address, bricks in sorted(parts.items())]
        stats = []
        first = True
        for address, bricks, future in futures:
            answers, part_stats = self._finish_part(
                address, future, rays.shape[0], lambda client, bricks=bricks: run_part(client, rays, bricks))
            if first:
                out[:] = answers
                first = False
            else:
                merge_nearest(out, answers)
            stats.append(part_stats)
        return stats

    def _finish_part(self, address, future, rays: int, run_again):
        """A part's answers; on UNAVAILABLE, the same part (run_again(client))
        from the next live replicas on the ring, in turn."""
        tried = {address}
        while True:
            try:
                return future.result()
            except OutcoreError as e:
                if e.code != "UNAVAILABLE":
                    raise
                self._mark_down(address)
                live = [a for a in self._live() if a not in tried]
                if not live:
                    raise OutcoreError("UNAVAILABLE", f"every replica failed for a part of {rays} rays; "
                                                      f"last: {e.details}") from None
                address = next(a for a in HashRing(self.replicas()).walk(_hash64(address)) if a in live)
                tried.add(address)
                with self._lock:
                    self.failovers += 1
                future = self._pool.submit(run_again, self.client(address))
