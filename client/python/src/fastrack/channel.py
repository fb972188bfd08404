"""Connection settings: the server address (one replica or several), TLS (server-verified or mutual), the
bearer token, per-call deadlines and the retry policy; builds the gRPC channels (sync and asyncio), one per
replica, from them."""

from __future__ import annotations

import ipaddress
import random
import socket
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

    One attempt is one pass over the replicas: the call goes to the next replica in turn and, while they
    answer ``UNAVAILABLE``, to the following ones, each once, without waiting; the backoff is between
    passes. So a call is made at most ``attempts`` x (number of replicas) times. ``Track`` streams (which
    move to another replica on their own) and admin calls (one replica, once) are never retried."""

    attempts: int = 5
    """Most passes over the replicas of one call, the first included (1: each replica once, no waiting)."""
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
class Endpoint:
    """One replica: where gRPC connects, and the name its TLS certificate is verified against when that
    is not the address itself."""

    target: str
    """``host:port`` (an IP address once a host name was resolved; IPv6 in brackets)."""
    server_name: str | None = None
    """The host name the address came from (TLS verifies the certificate against it); None for an IP."""


@dataclass(frozen=True)
class Settings:
    """Everything a client needs to connect; built by :class:`fastrack.Client` from its arguments."""

    address: str
    """``host:port``, ``http://host:port`` or ``https://host:port`` (https needs ``tls``); several separated
    by commas, one per replica."""
    timeout: float = DEFAULT_TIMEOUT_S
    """Default deadline of unary calls, and how long a replica may take to open a ``Track`` stream or answer
    a tick before it is passed over as gone, seconds."""
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

    def endpoints(self) -> list[Endpoint]:
        """The replicas the address names: each comma-separated item, a host name standing for every address
        it resolves to (``socket.getaddrinfo``, once, now). Checks each item's scheme against the TLS settings.
        A name that does not resolve now is kept as one replica that gRPC resolves when it connects."""
        items = [item.strip() for item in self.address.split(",")]
        for number, item in enumerate(items, 1):
            if not item:
                raise ConfigError(
                    f"invalid server address {self.address!r}: item {number} of the comma-separated list is empty"
                )
        found: list[Endpoint] = []
        for item in items:
            found += self._resolve(item)
        return found

    def _resolve(self, item: str) -> list[Endpoint]:
        scheme, sep, rest = item.partition("://")
        host_port = (rest if sep else item).rstrip("/")
        if sep and scheme not in ("http", "https"):
            raise ConfigError(f"invalid server address {item!r}: the scheme must be http or https")
        if scheme == "https" and sep and self.tls is None:
            raise ConfigError(f"{item}: an https:// address needs TLS settings (a CA certificate)")
        if scheme == "http" and sep and self.tls is not None:
            raise ConfigError(f"{item}: TLS is configured, so the address must start with https://")
        host, _, port = host_port.rpartition(":")
        if not host or not port.isdigit():
            raise ConfigError(f"invalid server address {item!r}: expected host:port")
        bare_host = host[1:-1] if host.startswith("[") and host.endswith("]") else host
        try:
            ipaddress.ip_address(bare_host)
            return [Endpoint(host_port)]
        except ValueError:
            pass  # a host name
        try:
            infos = socket.getaddrinfo(bare_host, int(port), type=socket.SOCK_STREAM)
        except (OSError, UnicodeError):
            return [Endpoint(host_port)]  # not resolvable now: gRPC resolves it itself when connecting
        ips = sorted(
            {ipaddress.ip_address(str(info[4][0]).partition("%")[0]) for info in infos},
            key=lambda ip: (ip.version, int(ip)),
        )
        if not ips:
            return [Endpoint(host_port)]
        return [Endpoint(f"{ip}:{port}" if ip.version == 4 else f"[{ip}]:{port}", bare_host) for ip in ips]

    @property
    def metadata(self) -> tuple[tuple[str, str], ...]:
        """Call metadata: the bearer token, if any."""
        return (("authorization", f"Bearer {self.token}"),) if self.token is not None else ()

    def channel_options(self, endpoint: Endpoint) -> list[tuple[str, str | int]]:
        backoff_ms = max(1, int(self.max_reconnect_backoff * 1000))
        options: list[tuple[str, str | int]] = [
            ("grpc.max_send_message_length", MAX_MESSAGE_BYTES),
            ("grpc.max_receive_message_length", MAX_MESSAGE_BYTES),
            ("grpc.initial_reconnect_backoff_ms", min(100, backoff_ms)),
            ("grpc.max_reconnect_backoff_ms", backoff_ms),
        ]
        server_name = (self.tls.domain or endpoint.server_name) if self.tls is not None else None
        if server_name is not None:
            options.append(("grpc.ssl_target_name_override", server_name))
        return options

    def sync_channel(self, endpoint: Endpoint, credentials: grpc.ChannelCredentials | None) -> grpc.Channel:
        """A channel to one replica (``credentials``: from :meth:`Tls.credentials`, None without TLS)."""
        options = self.channel_options(endpoint)
        if credentials is None:
            return grpc.insecure_channel(endpoint.target, options=options)
        return grpc.secure_channel(endpoint.target, credentials, options=options)

    def aio_channel(self, endpoint: Endpoint, credentials: grpc.ChannelCredentials | None) -> grpc.aio.Channel:
        """An asyncio channel to one replica."""
        options = self.channel_options(endpoint)
        if credentials is None:
            return grpc.aio.insecure_channel(endpoint.target, options=options)
        return grpc.aio.secure_channel(endpoint.target, credentials, options=options)

    def credentials(self) -> grpc.ChannelCredentials | None:
        """The TLS credentials shared by every replica's channel; None without TLS."""
        return self.tls.credentials() if self.tls is not None else None
