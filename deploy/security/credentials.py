"""What keeps one local run to itself: run keys, a private directory, and in secure mode an
ephemeral certificate authority with a certificate and an access control for each process.

* Run keys (bestofn_swarm/wire/auth.py): a fresh secret per run. The world server, beacon and
  recorder get it; each robot process gets only the keys of the robots it hosts. Keys go
  through each child's environment or the fork call, never a command line.
* The private directory (mode 0700, removed by ``close``, and by its janitor however the
  launcher ends: deploy/security/janitor.py) holds the router's Unix socket:
  a run's router is then reachable by this user only, not by every user of the machine as
  a loopback TCP port is. In secure mode it also holds the CA, the certificates and the
  Zenoh configurations, and the router listens on TLS on loopback instead, with the
  access control of deploy/security/zenoh_acl.py (each process may publish only on its own keys)
  and certificates from an authority made for the run (deploy/security/certificates.py).
"""

from __future__ import annotations

import socket
import tempfile
import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from pathlib import Path

from bestofn_swarm.plumbing import run_keys
from bestofn_swarm.plumbing.tcp import free_port, wait_for_port
from bestofn_swarm.wire import auth, keyspace, names, protocol
from deploy.security import certificates, zenoh_acl
from deploy.security.janitor import PREFIX, PrivateDirectory

DIRECTORY_PREFIX = PREFIX
SOCKET_NAME = "zenoh.sock"
SOCKET_PATH_LIMIT = 100  # bytes: sun_path holds 108 with its terminating zero
CERTIFICATE_DAYS = 1  # ephemeral: the run's certificates are removed with it anyway
BEACON = names.DEFAULT_BEACON


def private_directory(*, janitor: bool = True) -> PrivateDirectory:
    """A new directory only this user can enter (mkdtemp makes it 0700), removed when this
    process ends however it ends (deploy/security/janitor.py)."""
    base = tempfile.gettempdir()
    if len(base) + len(DIRECTORY_PREFIX) + 10 + len(SOCKET_NAME) > SOCKET_PATH_LIMIT:
        base = "/tmp"  # a socket path must be short
    return PrivateDirectory.create(base, janitor=janitor)


def socket_endpoint(directory: Path) -> str:
    return f"unixsock-stream/{directory / SOCKET_NAME}"


def wait_for_socket(path: Path, timeout: float, alive: Callable[[], bool]) -> bool:
    """Wait until something accepts connections on the Unix socket at ``path``."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline and alive():
        with socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) as probe:
            probe.settimeout(0.2)
            if probe.connect_ex(str(path)) == 0:
                return True
        time.sleep(0.05)
    return False


@dataclass
class RunNetwork:
    """Where one run's processes meet, and what each of them is given to take part."""

    run_id: str
    endpoint: str  # what clients connect to
    router: bool  # the world server is the run's router (else it is a client of --connect)
    keyring: auth.Keyring | None  # None: an unauthenticated run (--no-keys)
    private: PrivateDirectory | None = None  # removed by close(), or by its janitor
    secure: bool = False

    @property
    def directory(self) -> Path | None:
        return self.private.path if self.private is not None else None

    @classmethod
    def create(
        cls,
        run_id: str,
        robots: int,
        *,
        connect: str | None = None,
        keyed: bool = True,
        secure: bool = False,
        root: str = protocol.DEFAULT_ROOT,
        janitor: bool = True,
    ) -> RunNetwork:
        """The run's keys and, unless ``connect``, its private directory (with its janitor,
        deploy/security/janitor.py), and in ``secure`` mode its certificates."""
        keyring = auth.Keyring(secret=run_keys.new_secret()) if keyed else None
        if connect is not None:
            return cls(run_id, connect, router=False, keyring=keyring)
        private = private_directory(janitor=janitor)
        directory = private.path
        try:
            if not secure:
                return cls(run_id, socket_endpoint(directory), True, keyring, private)
            port = free_port()
            plan = zenoh_acl.SwarmPlan(
                keyspace.Keys(run_id, root), tuple(range(robots)), (BEACON,), port=port
            )
            cert_dir = directory / "certs"
            ca, ca_key = directory / "ca.pem", directory / "ca.key"
            certificates.create_ca(ca, ca_key, days=CERTIFICATE_DAYS)
            certificates.issue_all(
                plan.routers,
                plan.client_identities(),
                ca,
                ca_key,
                cert_dir,
                days=CERTIFICATE_DAYS,
            )
            ca_key.unlink()  # nothing more to sign: no process needs it
            zenoh_acl.write_configs(plan, directory, cert_dir)
            endpoint = f"tls/127.0.0.1:{port}"
            return cls(run_id, endpoint, True, keyring, private, secure=True)
        except BaseException:
            private.close()
            raise

    # --- what each process is given --------------------------------------------------

    def world_args(self) -> list[str]:
        if not self.router:
            return ["--mode", "client", "--connect", self.endpoint]
        args = ["--mode", "router", "--listen", self.endpoint]
        if self.secure:
            args += ["--zenoh-config", str(self.config_of(zenoh_acl.DEFAULT_ROUTER, "routers"))]
        return args

    def client_args(self, identity: str) -> list[str]:
        """Options of a client process; ``identity`` is its certificate's name, with
        ``{id}`` standing for each robot of a robot process."""
        args = ["--mode", "client", "--connect", self.endpoint]
        if self.secure:
            args += ["--zenoh-config", str(self.config_of(identity))]
        return args

    def config_of(self, identity: str, folder: str = "clients") -> Path | None:
        """The Zenoh configuration file of ``identity`` in secure mode (else None)."""
        if not self.secure or self.directory is None:
            return None
        return self.directory / folder / f"{identity}.json5"

    def env(self, identities: Iterable[str] | None = None) -> dict[str, str]:
        """The environment that hands a child its keys: the run secret, or (a robot
        process) only the keys of ``identities``."""
        if self.keyring is None:
            return {}
        keyring = self.keyring if identities is None else self.keyring.only(identities)
        return {run_keys.KEYS_ENV: run_keys.to_text(keyring, self.run_id)}

    def wait_for_router(self, timeout: float, alive: Callable[[], bool]) -> bool:
        """Wait until the world server listens (nothing to wait for with --connect)."""
        if not self.router:
            return True
        if self.endpoint.startswith("unixsock-stream/"):
            return wait_for_socket(Path(self.endpoint.partition("/")[2]), timeout, alive)
        return wait_for_port(int(self.endpoint.rsplit(":", 1)[1]), timeout, alive)

    def close(self) -> None:
        """Remove the private directory: the socket, certificates and keys go with it."""
        if self.private is not None:
            self.private.close()
            self.private = None
