"""Start a private Mosquitto on a free loopback port, with its own config file (system tests):
anonymous, with one login, or with a password file and an ACL (``make-credentials``), the
dynamic-security plugin, and TLS listeners.

Tests that need it skip when the binary is missing, unless ``VDA_REQUIRE_MOSQUITTO`` is set (CI
sets it), in which case they fail instead of hiding behind a skip.
"""

from __future__ import annotations

import base64
import hashlib
import json
import os
import secrets
import shutil
import socket
import subprocess
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

import pytest

from vda5050.broker import BrokerAddress


def mosquitto_binary() -> str | None:
    """Path of the mosquitto binary, also where Debian puts it outside PATH."""
    found = shutil.which("mosquitto")
    if found:
        return found
    return "/usr/sbin/mosquitto" if Path("/usr/sbin/mosquitto").is_file() else None


def require_mosquitto() -> str:
    """The binary, or skip (fail when VDA_REQUIRE_MOSQUITTO is set) when it is missing."""
    binary = mosquitto_binary()
    if binary is None:
        if os.environ.get("VDA_REQUIRE_MOSQUITTO"):
            pytest.fail("mosquitto is required (VDA_REQUIRE_MOSQUITTO is set) but not installed")
        pytest.skip("mosquitto is not installed")
    return binary


def free_port() -> int:
    """A port free for a server to listen on, chosen below the kernel's ephemeral range: a
    port the kernel hands out (bind to 0) can be taken by any outgoing connection before the
    server binds it, which made tests fail with "Address already in use"."""
    low, high = 10_000, _ephemeral_start() - 1
    for _ in range(50):
        port = secrets.randbelow(high - low) + low
        with socket.socket() as sock:
            try:
                sock.bind(("127.0.0.1", port))
            except OSError:
                continue
            return port
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        chosen: int = sock.getsockname()[1]
        return chosen


def _ephemeral_start() -> int:
    """The first port of the kernel's ephemeral range (Linux; 32768 where unknown)."""
    try:
        first = Path("/proc/sys/net/ipv4/ip_local_port_range").read_text().split()[0]
    except (OSError, IndexError):
        return 32_768
    return max(int(first), 12_000)


@dataclass
class Mosquitto:
    """A running private Mosquitto."""

    address: BrokerAddress
    process: subprocess.Popen[bytes]
    config: Path
    log: Path

    def stop(self) -> None:
        if self.process.poll() is None:
            self.process.terminate()
            try:
                self.process.wait(5)
            except subprocess.TimeoutExpired:
                self.process.kill()
                self.process.wait(5)

    def start(self) -> None:
        """(Re)start on the same port with the same config."""
        self.process = _spawn(mosquitto_binary() or "mosquitto", self.config, self.log)
        wait_listening(self.address, self.process, self.log)


def _spawn(binary: str, config: Path, log: Path) -> subprocess.Popen[bytes]:
    with log.open("ab") as sink:
        return subprocess.Popen([binary, "-c", str(config)], stdout=sink, stderr=sink)  # noqa: S603


def wait_listening(
    address: BrokerAddress, process: subprocess.Popen[bytes] | None = None, log: Path | None = None
) -> None:
    """Until something listens on ``address``; RuntimeError if ``process`` exits first."""
    deadline = time.monotonic() + 10
    while time.monotonic() < deadline:
        if process is not None and process.poll() is not None:
            tail = log.read_text()[-2000:] if log is not None else ""
            msg = f"the broker exited with {process.returncode}: {tail}"
            raise RuntimeError(msg)
        try:
            with socket.create_connection((address.host, address.port), timeout=0.2):
                return
        except OSError:
            time.sleep(0.02)
    msg = f"no broker listened on {address.url} within 10 s"
    raise RuntimeError(msg)


@dataclass(frozen=True)
class TlsListener:
    """A TLS listener: the server's certificate and key, the CA that clients must be signed by
    (``require_certificate``) and its port."""

    port: int
    ca_file: Path
    cert_file: Path
    key_file: Path
    require_certificate: bool = False

    def lines(self, host: str) -> list[str]:
        return [
            f"listener {self.port} {host}",
            f"cafile {self.ca_file}",
            f"certfile {self.cert_file}",
            f"keyfile {self.key_file}",
            f"require_certificate {'true' if self.require_certificate else 'false'}",
        ]


@dataclass(frozen=True)
class DynsecClient:
    """A login of the dynamic-security plugin with its ACL entries: (acltype, topic, allow),
    acltype one of publishClientSend, publishClientReceive, subscribePattern, ..."""

    username: str
    password: str
    acls: tuple[tuple[str, str, bool], ...]


def dynsec_plugin() -> Path | None:
    """The dynamic-security plugin of the installed Mosquitto, if any."""
    for directory in ("/usr/lib/x86_64-linux-gnu", "/usr/lib/aarch64-linux-gnu", "/usr/lib"):
        candidate = Path(directory) / "mosquitto_dynamic_security.so"
        if candidate.is_file():
            return candidate
    return None


def write_dynsec(path: Path, clients: list[DynsecClient]) -> None:
    """A dynamic-security config (Mosquitto 2.0 format): every client gets its own role; by
    default nothing may be published or subscribed."""
    entries, roles = [], []
    for client in clients:
        salt = secrets.token_bytes(12)
        digest = hashlib.pbkdf2_hmac("sha512", client.password.encode(), salt, 101, 64)
        entries.append(
            {
                "username": client.username,
                "password": base64.b64encode(digest).decode(),
                "salt": base64.b64encode(salt).decode(),
                "iterations": 101,
                "roles": [{"rolename": f"role-{client.username}"}],
            }
        )
        acls = [{"acltype": t, "topic": topic, "allow": allow} for t, topic, allow in client.acls]
        roles.append({"rolename": f"role-{client.username}", "acls": acls})
    default = {
        "publishClientSend": False,
        "publishClientReceive": True,
        "subscribe": False,
        "unsubscribe": True,
    }
    path.write_text(json.dumps({"clients": entries, "roles": roles, "defaultACLAccess": default}))


@contextmanager
def run_mosquitto(
    directory: Path,
    *,
    credentials: tuple[str, str] | None = None,
    port: int | None = None,
    password_file: Path | None = None,
    acl_file: Path | None = None,
    dynsec: list[DynsecClient] | None = None,
    tls: tuple[TlsListener, ...] = (),
) -> Iterator[Mosquitto]:
    """Run Mosquitto on a free port; with ``credentials`` only that user may connect, with
    ``password_file`` and ``acl_file`` (make-credentials) those, with ``dynsec`` the plugin's
    clients. ``tls`` adds TLS listeners (the plain one stays)."""
    binary = require_mosquitto()
    directory.mkdir(parents=True, exist_ok=True)
    address = BrokerAddress("127.0.0.1", port or free_port())
    closed = credentials or password_file or dynsec
    lines = [
        f"listener {address.port} {address.host}",
        "set_tcp_nodelay true",
        "persistence false",
        "max_queued_messages 100000",
        f"allow_anonymous {'false' if closed else 'true'}",
    ]
    if os.geteuid() == 0:
        lines.append("user root")  # else it drops to 'mosquitto' and cannot read our files
    if password_file is not None:
        lines.append(f"password_file {password_file}")
    if acl_file is not None:
        lines.append(f"acl_file {acl_file}")
    if dynsec is not None:
        plugin = dynsec_plugin()
        if plugin is None:
            pytest.fail("Mosquitto's dynamic-security plugin is not installed")
        config_file = directory / "dynsec.json"
        write_dynsec(config_file, dynsec)
        lines += [f"plugin {plugin}", f"plugin_opt_config_file {config_file}"]
    for listener in tls:
        lines += listener.lines(address.host)
    if credentials:
        password_file = directory / "passwords"
        password_file.write_text("")
        subprocess.run(  # noqa: S603
            [
                shutil.which("mosquitto_passwd") or "mosquitto_passwd",
                "-b",
                str(password_file),
                *credentials,
            ],
            check=True,
            capture_output=True,
        )
        password_file.chmod(0o600)
        lines.append(f"password_file {password_file}")
    config = directory / "mosquitto.conf"
    config.write_text("\n".join(lines) + "\n")
    log = directory / "mosquitto.log"
    process = _spawn(binary, config, log)
    broker = Mosquitto(address, process, config, log)
    try:
        wait_listening(address, process, log)
        yield broker
    finally:
        broker.stop()
