"""The dynamic layer's calls of SceneClient (AddMesh, AddInstance,
UpdateTransforms, UpdateVertices, Remove; docs/PYTHON.md, "Dynamic
geometry"), as a mixin: SceneClient provides _channel, _call_plain,
_router and last_dynamic_version."""

from __future__ import annotations

import numpy as np

from .errors import OutcoreError
from .v1 import scene_query_pb2 as pb

_SERVICE = pb.DESCRIPTOR.services_by_name["SceneQuery"].full_name


def _vertex_array(values, name: str) -> np.ndarray:
    a = np.asarray(values)
    if a.ndim != 2 or a.shape[1] != 3 or not (np.issubdtype(a.dtype, np.floating) or np.issubdtype(a.dtype, np.integer)):
        raise ValueError(f"{name} must be an (N, 3) array of numbers, got shape {a.shape} dtype {a.dtype}")
    return np.ascontiguousarray(a, dtype="<f4")


def _index_array(values, name: str) -> np.ndarray:
    a = np.asarray(values)
    if a.ndim != 2 or a.shape[1] != 3 or not np.issubdtype(a.dtype, np.integer):
        raise ValueError(f"{name} must be an (M, 3) array of integers, got shape {a.shape} dtype {a.dtype}")
    if a.size and (a.min() < 0 or a.max() > 0xFFFFFFFF):
        raise ValueError(f"{name} holds an index outside 0..4294967295")
    return np.ascontiguousarray(a, dtype="<u4")


def _transforms(values, count: int, name: str) -> np.ndarray:
    a = np.asarray(values, dtype=np.float64)
    if a.size != 12 * count:
        raise ValueError(f"{name} must hold 12 numbers ((3, 4)) per instance: {count} instances, got {a.size}")
    return a.reshape(-1)


def _uint32(value, name: str) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or not 0 <= value <= 0xFFFFFFFF:
        raise ValueError(f"{name} must be an int in 0..4294967295, got {value!r}")
    return int(value)


def dynamic_calls(channel) -> dict:
    """The dynamic layer's callables on `channel`, by method name."""
    return {
        name: channel.unary_unary(
            f"/{_SERVICE}/{name}",
            request_serializer=request.SerializeToString,
            response_deserializer=response.FromString,
        )
        for name, request, response in (
            ("AddMesh", pb.AddMeshRequest, pb.AddMeshResponse),
            ("AddInstance", pb.AddInstanceRequest, pb.AddInstanceResponse),
            ("UpdateTransforms", pb.UpdateTransformsRequest, pb.DynamicVersion),
            ("UpdateVertices", pb.UpdateVerticesRequest, pb.DynamicVersion),
            ("Remove", pb.RemoveRequest, pb.DynamicVersion),
        )
    }


class DynamicLayerCalls:
    """The dynamic layer's methods of SceneClient."""

    def add_mesh(self, vertices, triangles) -> int:
        """Adds a mesh to the server's dynamic layer: vertices (N, 3) real,
        triangles (M, 3) vertex indices. Returns its mesh id (0, 1, ... in
        order of addition); it is traced only once placed by add_instance.
        Every change makes a new version (last_dynamic_version); a bad mesh
        (non-finite vertex, index out of range) is OutcoreError
        INVALID_ARGUMENT naming it, and changes nothing."""
        v = _vertex_array(vertices, "vertices")
        t = _index_array(triangles, "triangles")
        self._refuse_dynamic_on_replicas()
        reply = self._call_plain(self._dynamic_calls["AddMesh"], pb.AddMeshRequest(
            vertex_count=v.shape[0], vertices=v.tobytes(), triangle_count=t.shape[0], triangles=t.tobytes()),
            "AddMesh")
        self.last_dynamic_version = reply.version
        return reply.mesh_id

    def add_instance(self, mesh_id: int, transform=None) -> int:
        """Places mesh `mesh_id` in the scene: transform (3, 4) (or 12 numbers,
        row-major; world = T[:, :3] @ object + T[:, 3]), identity if None.
        Returns the instance's geometry id (hits report it; ids continue after
        the packed inputs' and are never reused)."""
        rows = _transforms(np.eye(3, 4) if transform is None else transform, 1, "transform")
        self._refuse_dynamic_on_replicas()
        reply = self._call_plain(self._dynamic_calls["AddInstance"], pb.AddInstanceRequest(
            mesh_id=_uint32(mesh_id, "mesh_id"), transform=rows.tolist()), "AddInstance")
        self.last_dynamic_version = reply.version
        return reply.geometry_id

    def update_transforms(self, geometry_ids, transforms) -> int:
        """New transforms ((K, 3, 4) or (K, 12)) for K instances, all at once
        (all or nothing). Returns the new version."""
        ids = np.asarray(geometry_ids).reshape(-1)
        rows = _transforms(transforms, ids.shape[0], "transforms")
        self._refuse_dynamic_on_replicas()
        reply = self._call_plain(self._dynamic_calls["UpdateTransforms"], pb.UpdateTransformsRequest(
            geometry_ids=[_uint32(i, "geometry_ids") for i in ids.tolist()], transforms=rows.tolist()),
            "UpdateTransforms")
        self.last_dynamic_version = reply.version
        return reply.version

    def update_vertices(self, mesh_id: int, vertices) -> int:
        """New positions for every vertex of a mesh ((N, 3), the same N: its
        topology is fixed); its instances move with it. Returns the new version."""
        v = _vertex_array(vertices, "vertices")
        self._refuse_dynamic_on_replicas()
        reply = self._call_plain(self._dynamic_calls["UpdateVertices"], pb.UpdateVerticesRequest(
            mesh_id=_uint32(mesh_id, "mesh_id"), vertex_count=v.shape[0], vertices=v.tobytes()),
            "UpdateVertices")
        self.last_dynamic_version = reply.version
        return reply.version

    def remove(self, geometry_id: int) -> int:
        """Removes an instance (its mesh stays). Returns the new version."""
        self._refuse_dynamic_on_replicas()
        reply = self._call_plain(self._dynamic_calls["Remove"],
                                 pb.RemoveRequest(geometry_id=_uint32(geometry_id, "geometry_id")), "Remove")
        self.last_dynamic_version = reply.version
        return reply.version

    def _refuse_dynamic_on_replicas(self) -> None:
        if self._router is not None:
            raise OutcoreError("FAILED_PRECONDITION", "the dynamic layer belongs to one server: with replicas "
                               "each would hold its own; connect to one replica to change it")
