"""TLS against the real server, with certificates made here: a CA, a server certificate for localhost and
127.0.0.1, a client certificate; server-verified TLS and mutual TLS (with bearer tokens)."""

from __future__ import annotations

import datetime
import ipaddress
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import pytest
from cryptography import x509
from cryptography.hazmat.primitives import hashes, serialization
from cryptography.hazmat.primitives.asymmetric import ec
from cryptography.x509.oid import ExtendedKeyUsageOID, NameOID

import fastrack
from conftest import MODEL, USER_TOKEN, Server


@dataclass(frozen=True)
class Pem:
    cert: bytes
    key: bytes


def _name(common_name: str) -> x509.Name:
    return x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, common_name)])


def _key_pem(key: ec.EllipticCurvePrivateKey) -> bytes:
    return key.private_bytes(serialization.Encoding.PEM, serialization.PrivateFormat.PKCS8, serialization.NoEncryption())


def make_ca(name: str) -> tuple[Pem, ec.EllipticCurvePrivateKey]:
    key = ec.generate_private_key(ec.SECP256R1())
    now = datetime.datetime.now(datetime.timezone.utc)
    cert = (
        x509.CertificateBuilder()
        .subject_name(_name(name))
        .issuer_name(_name(name))
        .public_key(key.public_key())
        .serial_number(x509.random_serial_number())
        .not_valid_before(now - datetime.timedelta(minutes=5))
        .not_valid_after(now + datetime.timedelta(days=1))
        .add_extension(x509.BasicConstraints(ca=True, path_length=None), critical=True)
        .add_extension(
            x509.KeyUsage(True, False, False, False, False, True, True, False, False), critical=True
        )
        .add_extension(x509.SubjectKeyIdentifier.from_public_key(key.public_key()), critical=False)
        .sign(key, hashes.SHA256())
    )
    return Pem(cert.public_bytes(serialization.Encoding.PEM), _key_pem(key)), key


def make_leaf(ca: Pem, ca_key: ec.EllipticCurvePrivateKey, name: str, server: bool) -> Pem:
    key = ec.generate_private_key(ec.SECP256R1())
    issuer = x509.load_pem_x509_certificate(ca.cert)
    now = datetime.datetime.now(datetime.timezone.utc)
    builder = (
        x509.CertificateBuilder()
        .subject_name(_name(name))
        .issuer_name(issuer.subject)
        .public_key(key.public_key())
        .serial_number(x509.random_serial_number())
        .not_valid_before(now - datetime.timedelta(minutes=5))
        .not_valid_after(now + datetime.timedelta(days=1))
        .add_extension(x509.BasicConstraints(ca=False, path_length=None), critical=True)
        .add_extension(
            x509.ExtendedKeyUsage([ExtendedKeyUsageOID.SERVER_AUTH if server else ExtendedKeyUsageOID.CLIENT_AUTH]),
            critical=False,
        )
        .add_extension(
            x509.AuthorityKeyIdentifier.from_issuer_public_key(ca_key.public_key()), critical=False
        )
    )
    if server:
        names = [x509.DNSName("localhost"), x509.IPAddress(ipaddress.ip_address("127.0.0.1"))]
        builder = builder.add_extension(x509.SubjectAlternativeName(names), critical=False)
    else:
        builder = builder.add_extension(x509.SubjectAlternativeName([x509.DNSName(name)]), critical=False)
    cert = builder.sign(ca_key, hashes.SHA256())
    return Pem(cert.public_bytes(serialization.Encoding.PEM), _key_pem(key))


@dataclass(frozen=True)
class Pki:
    ca: Pem
    server: Pem
    client: Pem
    other_ca: Pem
    dir: Path


@pytest.fixture(scope="module")
def pki(tmp_path_factory: pytest.TempPathFactory) -> Pki:
    ca, ca_key = make_ca("fastrack test CA")
    other_ca, _ = make_ca("another CA")
    pki = Pki(ca, make_leaf(ca, ca_key, "localhost", True), make_leaf(ca, ca_key, "robot-7", False), other_ca,
              tmp_path_factory.mktemp("pki"))
    for name, data in [("ca.pem", ca.cert), ("server.pem", pki.server.cert), ("server.key", pki.server.key),
                       ("client.pem", pki.client.cert), ("client.key", pki.client.key)]:
        (pki.dir / name).write_bytes(data)
    return pki


@pytest.fixture(scope="module")
def tls_server(pki: Pki) -> Iterator[Server]:
    server = Server("--tls-cert", str(pki.dir / "server.pem"), "--tls-key", str(pki.dir / "server.key")).start()
    yield server.wait_serving(tls=fastrack.Tls(ca=pki.ca.cert, domain="localhost"))
    server.close()


@pytest.fixture(scope="module")
def mtls_server(pki: Pki) -> Iterator[Server]:
    args = ["--tls-cert", str(pki.dir / "server.pem"), "--tls-key", str(pki.dir / "server.key")]
    args += ["--tls-client-ca", str(pki.dir / "ca.pem"), "--tokens", f"user:{USER_TOKEN}"]
    server = Server(*args).start()
    tls = fastrack.Tls(ca=pki.ca.cert, cert=pki.client.cert, key=pki.client.key)
    yield server.wait_serving(tls=tls)
    server.close()


def test_server_tls(pki: Pki, tls_server: Server) -> None:
    port = tls_server.port
    with fastrack.Client(f"https://localhost:{port}", tls=fastrack.Tls(ca=pki.ca.cert)) as client:
        assert client.query_planner_control(MODEL, 2.5).beta_query == pytest.approx(0.75)
        with client.track(MODEL) as robot:
            assert robot.tick([0.0, 0.0, 0.0, 1.0], [0.0, 0.0]).seq == 0
    # The certificate also names 127.0.0.1; the CA may be given as a file path.
    with fastrack.Client(f"127.0.0.1:{port}", tls=fastrack.Tls(ca=str(pki.dir / "ca.pem"))) as client:
        assert client.health() == "SERVING"
    # A server certificate from another CA is refused.
    other = fastrack.Tls(ca=pki.other_ca.cert)
    with fastrack.Client(f"localhost:{port}", tls=other, retry=fastrack.Retry(attempts=1)) as client:
        with pytest.raises(fastrack.Unavailable):
            client.list_models()
    # Plaintext to a TLS port fails too.
    with fastrack.Client(f"127.0.0.1:{port}", retry=fastrack.Retry(attempts=1), timeout=2.0) as client:
        with pytest.raises((fastrack.Unavailable, fastrack.DeadlineExceeded)):
            client.list_models()


def test_mutual_tls_with_a_token(pki: Pki, mtls_server: Server) -> None:
    address = f"localhost:{mtls_server.port}"
    tls = fastrack.Tls(ca=pki.dir / "ca.pem", cert=pki.dir / "client.pem", key=pki.dir / "client.key")
    with fastrack.Client(address, tls=tls, token=USER_TOKEN) as client:
        assert [m.name for m in client.list_models()] == ["dubins4d", "untrained-dubins4d"]
    with fastrack.Client(address, tls=tls) as client:  # the certificate alone is not enough: tokens too
        with pytest.raises(fastrack.Unauthenticated):
            client.list_models()
    no_cert = fastrack.Tls(ca=pki.ca.cert)
    with fastrack.Client(address, tls=no_cert, token=USER_TOKEN, retry=fastrack.Retry(attempts=1)) as client:
        with pytest.raises(fastrack.Unavailable):
            client.list_models()
    with pytest.raises(fastrack.ConfigError, match="must be given together"):
        fastrack.Client(address, tls=fastrack.Tls(ca=pki.ca.cert, cert=pki.client.cert))
    with pytest.raises(fastrack.ConfigError, match="client key: no PEM PRIVATE KEY"):
        fastrack.Client(address, tls=fastrack.Tls(ca=pki.ca.cert, cert=pki.client.cert, key=pki.client.cert))


async def test_async_mutual_tls(pki: Pki, mtls_server: Server) -> None:
    tls = fastrack.Tls(ca=pki.ca.cert, cert=pki.client.cert, key=pki.client.key, domain="localhost")
    async with fastrack.AsyncClient(f"https://127.0.0.1:{mtls_server.port}", tls=tls, token=USER_TOKEN) as client:
        assert (await client.tracking_error_bound(MODEL, 1.0)).table_beta == pytest.approx(1.0)
        async with client.track(MODEL) as robot:
            assert (await robot.tick([0.0, 0.0, 0.0, 1.0], [0.0, 0.0])).seq == 0
