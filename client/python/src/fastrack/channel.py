"""Connection settings: the server address, TLS (server-verified or mutual), the bearer token, per-call
deadlines and the retry policy; builds the gRPC channels (sync and asyncio) from them."""

from __future__ import annotations

import random
from dataclasses import dataclass, field
from pathlib import Path

import grpc
import grpc.aio

from .errors import ConfigError

DEFAULT_TIMEOUT_S = 5.0
"""Deadline of each unary call, seconds (sent to the server as ``grpc-timeout``)."""
MAX_MESSAGE_BYTES = 16 << 20
"""Largest message sent or received, bytes (the server's default limit)."""


def _pem(what: str, data: bytes | str | Path, marker: str) -> bytes:
    """PEM bytes from bytes, a PEM string, or a file path; checked to hold ``marker``."""
    if isinstance(data, Path) or (isinstance(data, str) and "-----BEGIN" not in data):
        path = Path(data)
        try:
            data = path.read_bytes()
        except OSError as e:
            raise ConfigError(f"TLS {what}: cannot read {path}: {e.strerror}") from None
    pem = data.encode() if isinstance(data, str) else data
    if marker.encode() not in pem:
        raise ConfigError(f"TLS {what}: no PEM {marker.strip('-').strip()} found")
    return pem


@dataclass(frozen=True)
class Tls:
    """TLS settings: the server is verified against ``ca``; with ``cert`` and ``key`` the client also
    presents a certificate (mutual TLS). Each may be PEM bytes, a PEM string or a file path."""

    ca: bytes | str | Path
    """PEM of the certificate authority that signed the server's certificate."""
    cert: bytes | str | Path | None = None
    """Client certificate chain (PEM), for mutual TLS; needs ``key``."""
    key: bytes | str | Path | None = None
    """Client private key (PEM), for mutual TLS; needs ``cert``."""
    domain: str | None = None
    """Server name to verify the certificate against; default: the address's host."""

    def credentials(self) -> grpc.ChannelCredentials:
        ca = _pem("CA certificate", self.ca, "-----BEGIN CERTIFICATE-----")
        if (self.cert is None) != (self.key is None):
            raise ConfigError("TLS: a client certificate and its key must be given together (mutual TLS)")
        cert = key = None
        if self.cert is not None and self.key is not None:
            cert = _pem("client certificate", self.cert, "-----BEGIN CERTIFICATE-----")
            key = _pem("client key", self.key, "PRIVATE KEY-----")
        return grpc.ssl_channel_credentials(root_certificates=ca, private_key=key, certificate_chain=cert)

    def __repr__(self) -> str:
        return f"Tls(ca=<set>, client_certificate={'<set>' if self.cert else None}, domain={self.domain!r})"


@dataclass(frozen=True)
class Retry:
    """Retries of the idempotent unary calls on ``UNAVAILABLE``, with jittered exponential backoff: the
    k-th wait is uniform in [0.5, 1] x min(``max_backoff``, ``initial_backoff`` x ``multiplier``^k).
    ``Track`` streams and admin calls are never retried."""

    attempts: int = 5
    """Most attempts of one call, the first included (1: no retry)."""
    initial_backoff: float = 0.1
    """First wait, seconds."""
    max_backoff: float = 2.0
    """Longest wait, seconds."""
    multiplier: float = 2.0
    """Growth of the wait per attempt."""

    def __post_init__(self) -> None:
        if self.attempts < 1 or self.initial_backoff < 0 or self.max_backoff < 0 or self.multiplier < 1:
            raise ConfigError(f"{self!r}: needs attempts >= 1, backoffs >= 0 s and multiplier >= 1")

    def delay(self, attempt: int) -> float:
        """Seconds to wait after failed attempt number ``attempt`` (0-based)."""
        ceiling = min(self.max_backoff, self.initial_backoff * self.multiplier**attempt)
        return ceiling * random.uniform(0.5, 1.0)


NO_RETRY = Retry(attempts=1)


@dataclass(frozen=True)
class Settings:
    """Everything a client needs to connect; built by :class:`fastrack.Client` from its arguments."""

    address: str
    """``host:port``, ``http://host:port`` or ``https://host:port`` (https needs ``tls``)."""
    timeout: float = DEFAULT_TIMEOUT_S
    """Default deadline of unary calls, seconds."""
    token: str | None = field(default=None, repr=False)
    """Bearer token, sent as ``authorization: Bearer <token>`` on every call."""
    tls: Tls | None = None
    """TLS settings; None: plaintext."""
    retry: Retry = Retry()
    """Retry policy of idempotent unary calls."""
    max_reconnect_backoff: float = 1.0
    """Longest wait of the channel between reconnection attempts to a lost server, seconds."""

    def __post_init__(self) -> None:
        if not self.timeout > 0:
            raise ConfigError(f"timeout = {self.timeout}; must be a positive number of seconds")
        if self.token is not None and not (self.token.isascii() and self.token.isprintable() and self.token):
            raise ConfigError("the bearer token must be non-empty printable ASCII, without line breaks")

    @property
    def target(self) -> str:
        """The address without its scheme, as gRPC wants it; checks the scheme against the TLS settings."""
        scheme, sep, rest = self.address.partition("://")
        host_port = rest if sep else self.address
        if sep and scheme not in ("http", "https"):
            raise ConfigError(f"invalid server address {self.address!r}: the scheme must be http or https")
        if scheme == "https" and sep and self.tls is None:
            raise ConfigError(f"{self.address}: an https:// address needs TLS settings (a CA certificate)")
        if scheme == "http" and sep and self.tls is not None:
            raise ConfigError(f"{self.address}: TLS is configured, so the address must start with https://")
        if not host_port.rpartition(":")[2].isdigit():
            raise ConfigError(f"invalid server address {self.address!r}: expected host:port")
        return host_port.rstrip("/")

    @property
    def metadata(self) -> tuple[tuple[str, str], ...]:
        """Call metadata: the bearer token, if any."""
        return (("authorization", f"Bearer {self.token}"),) if self.token is not None else ()

    def channel_options(self) -> list[tuple[str, str | int]]:
        backoff_ms = max(1, int(self.max_reconnect_backoff * 1000))
        options: list[tuple[str, str | int]] = [
            ("grpc.max_send_message_length", MAX_MESSAGE_BYTES),
            ("grpc.max_receive_message_length", MAX_MESSAGE_BYTES),
            ("grpc.initial_reconnect_backoff_ms", min(100, backoff_ms)),
            ("grpc.max_reconnect_backoff_ms", backoff_ms),
        ]
        if self.tls is not None and self.tls.domain is not None:
            options.append(("grpc.ssl_target_name_override", self.tls.domain))
        return options

    def sync_channel(self) -> grpc.Channel:
        target, options = self.target, self.channel_options()
        if self.tls is None:
            return grpc.insecure_channel(target, options=options)
        return grpc.secure_channel(target, self.tls.credentials(), options=options)

    def aio_channel(self) -> grpc.aio.Channel:
        target, options = self.target, self.channel_options()
        if self.tls is None:
            return grpc.aio.insecure_channel(target, options=options)
        return grpc.aio.secure_channel(target, self.tls.credentials(), options=options)
