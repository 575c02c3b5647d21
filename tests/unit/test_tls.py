"""TLS settings: files checked at start-up, handshake errors turned into hints (issue 14)."""

from __future__ import annotations

import ssl
from pathlib import Path

import pytest
import trustme

from vda5050.config import BrokerConnectionConfig
from vda5050.errors import ConfigError
from vda5050.mqtt import MqttSession
from vda5050.tls import TlsFiles, tls_context, tls_hint


@pytest.fixture
def pki(tmp_path: Path) -> dict[str, Path]:
    """A CA, and a client certificate and key it signed, as PEM files."""
    ca = trustme.CA()
    client = ca.issue_cert("robot-0.example")
    files = {
        "ca": tmp_path / "ca.pem",
        "cert": tmp_path / "client.pem",
        "key": tmp_path / "key.pem",
    }
    ca.cert_pem.write_to_path(str(files["ca"]))
    client.cert_chain_pems[0].write_to_path(str(files["cert"]))
    client.private_key_pem.write_to_path(str(files["key"]))
    return files


def test_context_trusts_only_the_ca_file_and_presents_the_client_certificate(
    pki: dict[str, Path],
) -> None:
    """With tls_ca_file only that CA is trusted; the client certificate is loaded."""
    context = tls_context(TlsFiles(pki["ca"], pki["cert"], pki["key"]))
    assert context.verify_mode is ssl.CERT_REQUIRED
    assert context.check_hostname
    assert len(context.get_ca_certs()) == 1


@pytest.mark.parametrize(
    ("key", "problem", "fragment"),
    [
        ("tls_ca_file", "missing", "cannot read it"),
        ("tls_ca_file", "garbage", "holds no usable PEM certificate"),
        ("tls_cert_file", "missing", "cannot read it"),
        ("tls_cert_file", "garbage", "not a PEM certificate"),
        ("tls_key_file", "missing", "cannot read it"),
    ],
)
def test_unusable_files_fail_at_start_up_naming_key_and_path(
    pki: dict[str, Path], tmp_path: Path, key: str, problem: str, fragment: str
) -> None:
    """A missing or malformed file is a ConfigError when the session is built, with the key,
    the path and what is wrong."""
    bad = tmp_path / f"{problem}.pem"
    if problem == "garbage":
        bad.write_text("not a certificate\n")
    files = {"tls_ca_file": pki["ca"], "tls_cert_file": pki["cert"], "tls_key_file": pki["key"]}
    files[key] = bad
    config = BrokerConnectionConfig(broker_url="mqtts://broker.example:8883", **files)
    with pytest.raises(ConfigError, match=fragment) as caught:
        MqttSession(config.mqtt_settings())
    assert key in str(caught.value)
    assert str(bad) in str(caught.value)


def test_a_key_without_its_certificate_is_refused(pki: dict[str, Path]) -> None:
    """tls_key_file alone cannot do anything: the message says to set both."""
    with pytest.raises(ConfigError, match="without tls_cert_file"):
        tls_context(TlsFiles(key_file=pki["key"]))


def test_tls_files_without_mqtts_are_refused(pki: dict[str, Path]) -> None:
    """A CA file with an mqtt:// URL would be silently unused: refused at start-up."""
    config = BrokerConnectionConfig(broker_url="mqtt://broker.example:1883", tls_ca_file=pki["ca"])
    with pytest.raises(ConfigError, match="not mqtts://"):
        MqttSession(config.mqtt_settings())


def test_mqtts_without_files_uses_the_system_trust_store() -> None:
    """mqtts:// alone builds a session (default trust store), the keys stay optional."""
    MqttSession(BrokerConnectionConfig(broker_url="mqtts://broker.example").mqtt_settings())


@pytest.mark.parametrize(
    ("error", "fragment"),
    [
        (
            (
                "[SSL: CERTIFICATE_VERIFY_FAILED] certificate verify failed: self-signed "
                "certificate in certificate chain (_ssl.c:1006)"
            ),
            "not signed by a CA in tls_ca_file (/etc/ca.pem): set tls_ca_file to the CA",
        ),
        (
            (
                "[SSL: CERTIFICATE_VERIFY_FAILED] certificate verify failed: Hostname mismatch, "
                "certificate is not valid for 'mqtt'. (_ssl.c:1006)"
            ),
            "does not name the host",
        ),
        (
            "[SSL: CERTIFICATE_VERIFY_FAILED] certificate verify failed: certificate has expired",
            "validity period",
        ),
        ("[SSL: TLSV13_ALERT_CERTIFICATE_REQUIRED] tlsv13 alert certificate required", "requires"),
        ("[SSL: TLSV1_ALERT_UNKNOWN_CA] tlsv1 alert unknown ca (_ssl.c:2580)", "refused this"),
        ("[SSL: WRONG_VERSION_NUMBER] wrong version number (_ssl.c:1006)", "does not speak TLS"),
        ("[Errno 104] Connection reset by peer", "is a TLS listener"),
        (
            (
                "Operation timed out failed to receive on socket: [SSL: "
                "TLSV13_ALERT_CERTIFICATE_REQUIRED] tlsv13 alert certificate required"
            ),
            "set tls_cert_file and tls_key_file",
        ),
    ],
)
def test_handshake_errors_get_a_hint(error: str, fragment: str) -> None:
    """OpenSSL's messages become what to change, naming the key involved."""
    hint = tls_hint(error, TlsFiles(ca_file=Path("/etc/ca.pem")))
    assert hint is not None
    assert fragment in hint


def test_hint_without_a_ca_file_points_at_the_system_store() -> None:
    """Without tls_ca_file the hint says the system store was used and names the key to set."""
    hint = tls_hint("certificate verify failed: unable to get local issuer certificate", TlsFiles())
    assert hint is not None
    assert "system's trust store" in hint
    assert "tls_ca_file" in hint


def test_other_errors_get_no_tls_hint() -> None:
    """A refused TCP connection is not a certificate problem."""
    assert tls_hint("[Errno 111] Connection refused", TlsFiles()) is None


def test_a_silent_close_before_connack_points_at_the_client_certificate() -> None:
    """A mutual-TLS listener's refusal can reach the client as a bare EOF (its alert lost when
    the CONNECT crosses the close): before CONNACK that means "set tls_cert_file"; with a
    certificate set, that the broker may have refused it."""
    eof = "Operation timed out failed to receive on socket: EOF occurred in violation of protocol"
    hint = tls_hint(eof, TlsFiles(ca_file=Path("/etc/ca.pem")), before_connack=True)
    assert hint is not None
    assert "set tls_cert_file and tls_key_file" in hint
    with_certificate = TlsFiles(Path("/etc/ca.pem"), Path("/etc/me.pem"), Path("/etc/me.key"))
    refused = tls_hint(eof, with_certificate, before_connack=True)
    assert refused is not None
    assert "refused this client's certificate (tls_cert_file)" in refused


def test_a_silent_close_of_an_established_connection_is_no_tls_problem() -> None:
    """After CONNACK an EOF is a lost connection (a broker restart), not a certificate problem."""
    eof = "failed to receive on socket: EOF occurred in violation of protocol"
    assert tls_hint(eof, TlsFiles(ca_file=Path("/etc/ca.pem"))) is None
