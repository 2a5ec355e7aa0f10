"""A certificate authority for a secured swarm (the cryptography package): a new CA, and
a key and certificate signed by it for each identity of a run (deploy/security/zenoh_acl.py says
which identities there are and what each may do).

Every certificate may authenticate a client (mutual TLS); a router's also names the
hosts it serves as. Keys are P-256, accepted by rustls (Zenoh's TLS) and zenoh-pico's
mbedTLS. Everything is written readable by its owner only, in folders made 0700
(bestofn_swarm/plumbing/private_files.py), and a CA given by path is read with a size limit.
"""

from __future__ import annotations

import datetime
import ipaddress
from collections.abc import Sequence
from pathlib import Path

from cryptography import x509
from cryptography.hazmat.primitives import hashes, serialization
from cryptography.hazmat.primitives.asymmetric import ec
from cryptography.x509.oid import ExtendedKeyUsageOID, NameOID

from bestofn_swarm.plumbing.bounded_read import CERTIFICATE_BYTES, read_bounded
from bestofn_swarm.plumbing.private_files import make_private_folder, write_private

# P-256 keys: small, fast to make, accepted by rustls (Zenoh's TLS) and zenoh-pico's mbedTLS.
_CURVE = ec.SECP256R1()
# A little slack before "now", so that a certificate made this instant is already valid
# for a peer whose clock is slightly behind.
_BACKDATE = datetime.timedelta(minutes=5)


def _key_pem(key: ec.EllipticCurvePrivateKey) -> bytes:
    return key.private_bytes(
        serialization.Encoding.PEM,
        serialization.PrivateFormat.PKCS8,
        serialization.NoEncryption(),
    )


def _validity(days: int) -> tuple[datetime.datetime, datetime.datetime]:
    now = datetime.datetime.now(datetime.UTC)
    return now - _BACKDATE, now + datetime.timedelta(days=days)


def create_ca(
    certificate: Path, key: Path, *, days: int = 365, common_name: str = "bestofn-swarm-ca"
) -> None:
    """A new self-signed certificate authority (refuses to overwrite an existing one)."""
    for path in (certificate, key):
        if path.exists():
            raise FileExistsError(f"{path} exists; not replacing a certificate authority")
        make_private_folder(path.parent)
    private = ec.generate_private_key(_CURVE)
    name = x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, common_name)])
    start, end = _validity(days)
    ca = (
        x509.CertificateBuilder()
        .subject_name(name)
        .issuer_name(name)
        .public_key(private.public_key())
        .serial_number(x509.random_serial_number())
        .not_valid_before(start)
        .not_valid_after(end)
        .add_extension(x509.BasicConstraints(ca=True, path_length=0), critical=True)
        .add_extension(
            x509.KeyUsage(
                digital_signature=False,
                content_commitment=False,
                key_encipherment=False,
                data_encipherment=False,
                key_agreement=False,
                key_cert_sign=True,
                crl_sign=True,
                encipher_only=False,
                decipher_only=False,
            ),
            critical=True,
        )
        .add_extension(x509.SubjectKeyIdentifier.from_public_key(private.public_key()), False)
        .sign(private, hashes.SHA256())
    )
    write_private(key, _key_pem(private))
    write_private(certificate, ca.public_bytes(serialization.Encoding.PEM))


def issue_certificate(
    ca_certificate: Path,
    ca_key: Path,
    common_name: str,
    out_dir: Path,
    *,
    server_names: Sequence[str] = (),
    days: int = 365,
) -> tuple[Path, Path]:
    """A key and a certificate signed by the CA, named ``<common_name>.key/.pem``.

    Every certificate may authenticate a client (mutual TLS); one with ``server_names``
    (host names or IP addresses) may also serve, for routers.
    """
    make_private_folder(out_dir)
    key, certificate = out_dir / f"{common_name}.key", out_dir / f"{common_name}.pem"
    authority_pem = read_bounded(ca_certificate, CERTIFICATE_BYTES, "CA certificate")
    authority = x509.load_pem_x509_certificate(authority_pem)
    signer_pem = read_bounded(ca_key, CERTIFICATE_BYTES, "CA key")
    signer = serialization.load_pem_private_key(signer_pem, password=None)
    if not isinstance(signer, ec.EllipticCurvePrivateKey):
        raise RuntimeError(f"{ca_key} is not an elliptic-curve key")
    private = ec.generate_private_key(_CURVE)
    usages = [ExtendedKeyUsageOID.CLIENT_AUTH]
    if server_names:
        usages.insert(0, ExtendedKeyUsageOID.SERVER_AUTH)
    start, end = _validity(days)
    builder = (
        x509.CertificateBuilder()
        .subject_name(x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, common_name)]))
        .issuer_name(authority.subject)
        .public_key(private.public_key())
        .serial_number(x509.random_serial_number())
        .not_valid_before(start)
        .not_valid_after(min(end, authority.not_valid_after_utc))
        .add_extension(x509.BasicConstraints(ca=False, path_length=None), critical=True)
        .add_extension(
            x509.KeyUsage(
                digital_signature=True,
                content_commitment=False,
                key_encipherment=False,
                data_encipherment=False,
                key_agreement=False,
                key_cert_sign=False,
                crl_sign=False,
                encipher_only=False,
                decipher_only=False,
            ),
            critical=True,
        )
        .add_extension(x509.ExtendedKeyUsage(usages), critical=False)
        .add_extension(
            x509.AuthorityKeyIdentifier.from_issuer_public_key(signer.public_key()), False
        )
    )
    if server_names:
        alternatives: list[x509.GeneralName] = [
            x509.IPAddress(ipaddress.ip_address(name)) if is_ip(name) else x509.DNSName(name)
            for name in server_names
        ]
        builder = builder.add_extension(x509.SubjectAlternativeName(alternatives), False)
    issued = builder.sign(signer, hashes.SHA256())
    write_private(key, _key_pem(private))
    write_private(certificate, issued.public_bytes(serialization.Encoding.PEM))
    return key, certificate


def issue_all(
    routers: Sequence[str],
    clients: Sequence[str],
    ca_certificate: Path,
    ca_key: Path,
    cert_dir: Path,
    *,
    days: int = 365,
) -> None:
    """Certificates for every router and client identity, plus ``ca.pem``."""
    make_private_folder(cert_dir)
    if ca_certificate.resolve() != (cert_dir / "ca.pem").resolve():
        ca_pem = read_bounded(ca_certificate, CERTIFICATE_BYTES, "CA certificate")
        write_private(cert_dir / "ca.pem", ca_pem)
    for router in routers:
        # Clients reach their own host's router on loopback; routers reach it by name.
        hosts = list(dict.fromkeys([router, "localhost", "127.0.0.1"]))
        issue_certificate(ca_certificate, ca_key, router, cert_dir, server_names=hosts, days=days)
    for identity in clients:
        issue_certificate(ca_certificate, ca_key, identity, cert_dir, days=days)


def is_ip(text: str) -> bool:
    """Whether ``text`` is an IPv4 or IPv6 address (else a host name, for a router)."""
    try:
        ipaddress.ip_address(text)
    except ValueError:
        return False
    return True
