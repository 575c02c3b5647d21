"""TLS for ``mqtts://`` brokers: the SSL context from the ``tls_*`` keys, and hints that turn
OpenSSL's messages into what to change (issue 14, item 5 "TLS").

- ``tls_ca_file``: the CA certificate(s) (PEM) that signed the broker's certificate; only these
  are trusted then. Without it, the system's trust store is used.
- ``tls_cert_file`` and ``tls_key_file``: this client's certificate and private key (PEM, key
  unencrypted) for a broker that requires client certificates (mutual TLS). A certificate file
  that also holds the key may be given alone.

A missing, unreadable or malformed file is a :class:`ConfigError` at start-up naming the key and
the path; a handshake that fails later is logged with :func:`tls_hint`.
"""

from __future__ import annotations

import functools
import logging
import ssl
from dataclasses import dataclass
from pathlib import Path

from vda5050.errors import ConfigError


@dataclass(frozen=True, slots=True)
class TlsFiles:
    """The ``tls_*`` settings of one client."""

    ca_file: Path | None = None
    cert_file: Path | None = None
    key_file: Path | None = None

    @property
    def given(self) -> bool:
        return any((self.ca_file, self.cert_file, self.key_file))


def tls_context(files: TlsFiles) -> ssl.SSLContext:
    """A client context that verifies the broker (and presents a certificate when given);
    ConfigError naming the key and the path for a file that cannot be used."""
    for key, path in (
        ("tls_ca_file", files.ca_file),
        ("tls_cert_file", files.cert_file),
        ("tls_key_file", files.key_file),
    ):
        if path is not None:
            _check_readable(key, path)
    if files.key_file is not None and files.cert_file is None:
        msg = f"tls_key_file {files.key_file} is set without tls_cert_file: set both for mutual TLS"
        raise ConfigError(msg)
    return _context(files)


@functools.cache
def _context(files: TlsFiles) -> ssl.SSLContext:
    """One context per set of files: a fleet of sessions in one process shares it."""
    try:
        context = ssl.create_default_context(
            cafile=str(files.ca_file) if files.ca_file is not None else None
        )
    except ssl.SSLError as exc:
        msg = f"tls_ca_file {files.ca_file} holds no usable PEM certificate ({exc.reason or exc})"
        raise ConfigError(msg) from None
    if files.cert_file is not None:
        try:
            context.load_cert_chain(files.cert_file, files.key_file)
        except ssl.SSLError as exc:
            key = f" and tls_key_file {files.key_file}" if files.key_file else ""
            msg = (
                f"tls_cert_file {files.cert_file}{key}: not a PEM certificate with its "
                f"unencrypted private key, or they do not match ({exc.reason or exc})"
            )
            raise ConfigError(msg) from None
    return context


def _check_readable(key: str, path: Path) -> None:
    try:
        with path.open("rb"):
            pass
    except OSError as exc:
        msg = f"{key} {path}: cannot read it ({exc.strerror or exc})"
        raise ConfigError(msg) from None


#: Fragments of OpenSSL messages (lower case) and what to do about them, first match wins.
_HINTS: tuple[tuple[tuple[str, ...], str], ...] = (
    (
        ("hostname mismatch", "ip address mismatch"),
        (
            "the broker's certificate does not name the host in broker_url: connect by a name or "
            "address its certificate lists (subjectAltName), or issue it one that does"
        ),
    ),
    (
        ("certificate has expired", "not yet valid"),
        (
            "the broker's certificate is outside its validity period (or this machine's clock is "
            "wrong)"
        ),
    ),
    (
        ("certificate verify failed",),
        (
            "certificate verify failed: the broker's certificate is not signed by {trust}: set "
            "tls_ca_file to the CA certificate (PEM) that signed it"
        ),
    ),
    (
        ("certificate required",),
        "the broker requires a client certificate: set tls_cert_file and tls_key_file",
    ),
    (
        ("unknown ca", "bad certificate", "certificate unknown", "unsupported certificate"),
        (
            "the broker refused this client's certificate (tls_cert_file): it must be signed by a "
            "CA the broker trusts (its cafile)"
        ),
    ),
    (
        ("wrong version number", "unknown protocol", "record layer failure", "packet length"),
        "the port does not speak TLS: use mqtt:// or the broker's TLS port",
    ),
    (
        ("connection reset by peer",),
        (
            "the broker closed the connection during the TLS handshake: check that this port "
            "is a TLS listener (else use mqtt://)"
        ),
    ),
)


def tls_hint(error: str, files: TlsFiles, *, before_connack: bool = False) -> str | None:
    """What to change for a failed TLS handshake whose error text is ``error``; None when the
    text is not a TLS problem this function knows. ``before_connack``: the connection ended
    before the broker answered CONNECT."""
    text = error.lower()
    if before_connack and _SILENT_CLOSE in text:
        return _silent_close_hint(files)
    trust = (
        f"a CA in tls_ca_file ({files.ca_file})"
        if files.ca_file is not None
        else "a CA in the system's trust store (tls_ca_file is not set)"
    )
    for fragments, hint in _HINTS:
        if any(fragment in text for fragment in fragments):
            return hint.format(trust=trust)
    return None


#: OpenSSL's text when the peer closes the TCP connection without a TLS close_notify.
_SILENT_CLOSE = "eof occurred in violation of protocol"


def _silent_close_hint(files: TlsFiles) -> str:
    """A broker that requires a client certificate checks it after a TLS 1.3 handshake has
    completed for the client; its "certificate required" alert is lost when the socket is reset
    under it (the client's CONNECT crossing the close), which leaves only an EOF."""
    if files.cert_file is None:
        return (
            "the broker closed the TLS connection before answering CONNECT, as a listener that "
            "requires a client certificate does: set tls_cert_file and tls_key_file (else see "
            "the broker's log)"
        )
    return (
        "the broker closed the TLS connection before answering CONNECT: it may have refused "
        "this client's certificate (tls_cert_file): it must be signed by a CA the broker trusts "
        "(else see the broker's log)"
    )


class TransportErrors(logging.Handler):
    """Keeps the last error the MQTT client library logged about its socket: a TLS alert that
    arrives after the handshake (TLS 1.3: "certificate required") surfaces only there, while
    the connect itself just times out."""

    def __init__(self) -> None:
        super().__init__(logging.ERROR)
        self.last: str | None = None

    def emit(self, record: logging.LogRecord) -> None:
        self.last = record.getMessage()
