"""OutcoreError: every failure of a call to the server.

gRPC errors are re-raised as OutcoreError carrying the status code's name
(e.g. "INVALID_ARGUMENT", "DEADLINE_EXCEEDED", "UNAVAILABLE") and the server's
message, so callers need not import grpc to handle them.
"""

from __future__ import annotations

import grpc


class OutcoreError(RuntimeError):
    """A failed call. ``code`` is the gRPC status code name, ``details`` the message."""

    def __init__(self, code: str, details: str, method: str | None = None):
        self.code = code
        self.details = details
        self.method = method
        where = f" ({method})" if method else ""
        super().__init__(f"{code}: {details}{where}")


def from_rpc_error(error: grpc.RpcError, method: str) -> OutcoreError:
    """Converts a grpc.RpcError (which is also a grpc.Call for real calls)."""
    code_fn = getattr(error, "code", None)
    details_fn = getattr(error, "details", None)
    code = code_fn() if callable(code_fn) else None
    details = details_fn() if callable(details_fn) else None
    name = code.name if isinstance(code, grpc.StatusCode) else "UNKNOWN"
    return OutcoreError(name, details or str(error), method)
