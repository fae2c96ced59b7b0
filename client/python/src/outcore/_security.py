"""The channel a SceneClient opens: plaintext, or TLS trusting a given CA
(with a client certificate for servers started with --tls-client-ca), and a
bearer token sent as "authorization: Bearer TOKEN" on every call (servers
started with --auth-token-file), added by one channel interceptor so that no
call can forget it.
"""

from __future__ import annotations

import os
from typing import NamedTuple

import grpc

_PemSource = str | bytes | os.PathLike | None


def _pem(value: _PemSource, name: str) -> bytes | None:
    """PEM bytes from bytes (the PEM itself) or a path to a PEM file."""
    if value is None:
        return None
    if isinstance(value, bytes):
        data = value
    elif isinstance(value, (str, os.PathLike)):
        try:
            with open(value, "rb") as f:
                data = f.read()
        except OSError as e:
            raise ValueError(f"{name}: cannot read {os.fspath(value)!r}: {e.strerror}") from None
    else:
        raise ValueError(f"{name} must be a path to a PEM file or the PEM bytes, got {type(value).__name__}")
    if b"-----BEGIN " not in data:
        raise ValueError(f"{name}: no PEM block in {value if not isinstance(value, bytes) else 'the bytes given'!r}")
    return data


def check_token(token: str | None) -> str | None:
    if token is None:
        return None
    if not isinstance(token, str) or not token:
        raise ValueError(f"token must be None or a non-empty str, got {token!r}")
    if any(ord(c) <= 0x20 or ord(c) == 0x7F for c in token):
        raise ValueError("token must be one word of visible characters (no spaces or control characters)")
    return token


class _CallDetails(NamedTuple):
    method: str
    timeout: float | None
    metadata: tuple | None
    credentials: grpc.CallCredentials | None
    wait_for_ready: bool | None
    compression: grpc.Compression | None


class _BearerToken(grpc.UnaryUnaryClientInterceptor, grpc.UnaryStreamClientInterceptor,
                   grpc.StreamUnaryClientInterceptor, grpc.StreamStreamClientInterceptor):
    def __init__(self, token: str):
        self._header = ("authorization", f"Bearer {token}")

    def _with_token(self, details):
        metadata = tuple(details.metadata or ()) + (self._header,)
        return _CallDetails(details.method, details.timeout, metadata, details.credentials,
                            getattr(details, "wait_for_ready", None), getattr(details, "compression", None))

    def intercept_unary_unary(self, continuation, details, request):
        return continuation(self._with_token(details), request)

    def intercept_unary_stream(self, continuation, details, request):
        return continuation(self._with_token(details), request)

    def intercept_stream_unary(self, continuation, details, request_iterator):
        return continuation(self._with_token(details), request_iterator)

    def intercept_stream_stream(self, continuation, details, request_iterator):
        return continuation(self._with_token(details), request_iterator)


def make_channel(address: str, options: list, tls_ca: _PemSource = None, tls_cert: _PemSource = None,
                 tls_key: _PemSource = None, token: str | None = None) -> grpc.Channel:
    """The channel for SceneClient (arguments as documented there)."""
    token = check_token(token)
    if tls_ca is None:
        if tls_cert is not None or tls_key is not None:
            raise ValueError("tls_cert/tls_key need TLS: give tls_ca (the CA that signed the server's certificate)")
        channel = grpc.insecure_channel(address, options=options)
    else:
        if (tls_cert is None) != (tls_key is None):
            raise ValueError("a client certificate needs both tls_cert and tls_key")
        credentials = grpc.ssl_channel_credentials(root_certificates=_pem(tls_ca, "tls_ca"),
                                                   private_key=_pem(tls_key, "tls_key"),
                                                   certificate_chain=_pem(tls_cert, "tls_cert"))
        channel = grpc.secure_channel(address, credentials, options=options)
    if token is not None:
        channel = grpc.intercept_channel(channel, _BearerToken(token))
    return channel
