"""Where the broker is and how to connect to it: :class:`BrokerEndpoint` (parsed from the
broker URL) and :class:`MqttSettings` (one session's connection settings). Re-exported by
:mod:`vda5050.mqtt`."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from urllib.parse import unquote, urlsplit

from vda5050.errors import ConfigError
from vda5050.tls import TlsFiles

__all__ = ["BrokerEndpoint", "MqttSettings"]

_DEFAULT_PORTS = {"mqtt": 1883, "mqtts": 8883}


@dataclass(frozen=True, slots=True)
class BrokerEndpoint:
    """Where the broker is, parsed from ``mqtt://[user:password@]host:port`` or ``mqtts://…``."""

    host: str
    port: int
    username: str | None = None
    password: str | None = None
    tls: bool = False

    @classmethod
    def from_url(cls, url: str) -> BrokerEndpoint:
        """Parse a broker URL, raising ConfigError with what is wrong."""
        parts = urlsplit(url)
        if parts.scheme not in _DEFAULT_PORTS:
            msg = f"broker url {url!r}: scheme must be mqtt:// or mqtts://"
            raise ConfigError(msg)
        if not parts.hostname:
            msg = f"broker url {url!r} has no host"
            raise ConfigError(msg)
        try:
            port = parts.port or _DEFAULT_PORTS[parts.scheme]
        except ValueError:
            msg = f"broker url {url!r} has an invalid port"
            raise ConfigError(msg) from None
        return cls(
            host=parts.hostname,
            port=port,
            username=unquote(parts.username) if parts.username else None,
            password=unquote(parts.password) if parts.password else None,
            tls=parts.scheme == "mqtts",
        )

    @property
    def display(self) -> str:
        """The URL without the password, for logs."""
        user = f"{self.username}@" if self.username else ""
        return f"{'mqtts' if self.tls else 'mqtt'}://{user}{self.host}:{self.port}"


@dataclass(frozen=True, slots=True)
class MqttSettings:
    """Connection settings of one session. Times in seconds."""

    url: str = "mqtt://127.0.0.1:1883"
    #: Login; when None, a user and password in the URL are used.
    username: str | None = None
    password: str | None = None
    client_id: str | None = None
    #: The broker declares the client dead after ~1.5× this without traffic (§6.14: ~15 s).
    keepalive_s: int = 15
    clean_session: bool = True
    connect_timeout_s: float = 5.0
    reconnect_min_s: float = 0.1
    #: Longest wait between two connection attempts (fully jittered, doubling from the least).
    reconnect_max_s: float = 5.0
    #: Messages the outbox holds before it drops the oldest kept command.
    outbox_limit: int = 10_000
    #: mqtts://: CA file (else the system store), client certificate and key (mutual TLS).
    tls_ca_file: Path | None = None
    tls_cert_file: Path | None = None
    tls_key_file: Path | None = None
    #: A publication on a verify_echo filter must come back within this many seconds.
    publish_check_s: float = 3.0

    @property
    def tls_files(self) -> TlsFiles:
        return TlsFiles(self.tls_ca_file, self.tls_cert_file, self.tls_key_file)

    @property
    def endpoint(self) -> BrokerEndpoint:
        """Where to connect and with which login (explicit username/password win over the URL's)."""
        parsed = BrokerEndpoint.from_url(self.url)
        return BrokerEndpoint(
            parsed.host,
            parsed.port,
            self.username if self.username is not None else parsed.username,
            self.password if self.password is not None else parsed.password,
            parsed.tls,
        )
