"""The stack over ``mqtts://`` against Mosquitto with a CA of the test's own (trustme): an order
FINISHES with a CA file and with mutual TLS; certificate mistakes get a hint, not a crash
(issue 14, item 5 "TLS")."""

from __future__ import annotations

import asyncio
import os
import ssl
import subprocess
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import aiomqtt
import httpx
import pytest
import trustme

from tests.mosquitto import (
    Mosquitto,
    TlsListener,
    free_port,
    require_mosquitto,
    run_mosquitto,
    wait_listening,
)
from tests.system.stack import REPO, ServiceProcess, Stack
from vda5050.broker import BrokerAddress

pytestmark = pytest.mark.mosquitto


@dataclass(frozen=True)
class Pki:
    """PEM files: the CA, the broker's certificate and key, a client's, and a stranger CA."""

    ca: Path
    server_cert: Path
    server_key: Path
    client_cert: Path
    client_key: Path
    other_ca: Path


@pytest.fixture
def pki(tmp_path: Path) -> Pki:
    """A CA that signs the broker (for 127.0.0.1) and one client; a second, unrelated CA."""
    directory = tmp_path / "pki"
    directory.mkdir()
    ca, other = trustme.CA(), trustme.CA()
    server = ca.issue_cert("127.0.0.1", "localhost")
    client = ca.issue_cert("vda-master.example")
    files = Pki(*(directory / name for name in ("ca", "srv", "srv-key", "cli", "cli-key", "x")))
    ca.cert_pem.write_to_path(str(files.ca))
    other.cert_pem.write_to_path(str(files.other_ca))
    for blob in server.cert_chain_pems:
        blob.write_to_path(str(files.server_cert), append=True)
    server.private_key_pem.write_to_path(str(files.server_key))
    client.cert_chain_pems[0].write_to_path(str(files.client_cert))
    client.private_key_pem.write_to_path(str(files.client_key))
    return files


@dataclass(frozen=True)
class TlsBroker:
    """Mosquitto with a TLS listener and a mutual-TLS listener (client certificate required)."""

    mosquitto: Mosquitto
    tls_port: int
    mutual_port: int

    def url(self, port: int) -> str:
        return f"mqtts://127.0.0.1:{port}"


@pytest.fixture
def tls_broker(tmp_path: Path, pki: Pki) -> Iterator[TlsBroker]:
    """Mosquitto listening with TLS on two free ports; one requires a client certificate."""
    tls_port, mutual_port = free_port(), free_port()
    listeners = tuple(
        TlsListener(port, pki.ca, pki.server_cert, pki.server_key, require_certificate=mutual)
        for port, mutual in ((tls_port, False), (mutual_port, True))
    )
    with run_mosquitto(tmp_path / "mosquitto", tls=listeners) as mosquitto:
        yield TlsBroker(mosquitto, tls_port, mutual_port)


async def test_order_over_mqtts_finishes_with_a_ca_file_and_with_mutual_tls(
    tls_broker: TlsBroker, pki: Pki, unique_interface_name: str, tmp_path: Path
) -> None:
    """The master connects with a client certificate to the listener that requires one, the
    vehicle with tls_ca_file only; POST /orders over 17, 12, 11 for robot_0 FINISHES."""
    stack = Stack(tls_broker.mosquitto, unique_interface_name, tmp_path)
    client_files = ["--tls-cert-file", str(pki.client_cert), "--tls-key-file", str(pki.client_key)]
    try:
        stack.start_master(
            "--tls-ca-file",
            str(pki.ca),
            *client_files,
            url=tls_broker.url(tls_broker.mutual_port),
        )
        stack.start_vehicle(
            "robot_0", "--tls-ca-file", str(pki.ca), url=tls_broker.url(tls_broker.tls_port)
        )
        async with httpx.AsyncClient(timeout=5) as http:
            await stack.wait_vehicle(http, "robot_0", lambda v: bool(v.get("available")))
            answer = await http.post(
                f"{stack.api}/orders",
                json={
                    "manufacturer": "vda-sim",
                    "serialNumber": "robot_0",
                    "route": ["17", "12", "11"],
                },
            )
            assert answer.status_code == 201, answer.text
            await stack.wait_order(http, answer.json()["orderId"], "FINISHED")
    finally:
        await stack.stop_all()
    assert "mqtt.tls_failed" not in stack.logs_text()


async def test_certificate_mistakes_get_a_hint_and_no_crash(
    tls_broker: TlsBroker, pki: Pki, unique_interface_name: str, tmp_path: Path
) -> None:
    """A vehicle trusting the wrong CA logs one ERROR mqtt.tls_failed saying to set
    tls_ca_file to the CA that signed the broker, and keeps retrying; one without a client
    certificate on the mutual-TLS port is told to set tls_cert_file; a missing CA file stops
    the service at start-up with exit code 2, naming the key and the path."""
    stack = Stack(tls_broker.mosquitto, unique_interface_name, tmp_path)
    missing = tmp_path / "no-such-ca.pem"
    try:
        wrong = stack.start_vehicle(
            "robot_0", "--tls-ca-file", str(pki.other_ca), url=tls_broker.url(tls_broker.tls_port)
        )
        no_certificate = stack.start_vehicle(
            "vehicle",
            *("--tls-ca-file", str(pki.ca), "--connect-timeout-s", "1"),
            url=tls_broker.url(tls_broker.mutual_port),
        )
        absent = stack.start_vehicle(
            "robot_1", "--tls-ca-file", str(missing), url=tls_broker.url(tls_broker.tls_port)
        )
        assert await absent.wait(20) == 2
        await _wait_for_log(wrong, '"event": "mqtt.reconnect_scheduled"', count=2)
        await _wait_for_log(no_certificate, '"event": "mqtt.tls_failed"')
        assert wrong.running, "a certificate problem must not end the service"
        assert no_certificate.running
    finally:
        await stack.stop_all()
    log = wrong.log()
    assert log.count('"event": "mqtt.tls_failed"') == 1
    assert f"not signed by a CA in tls_ca_file ({pki.other_ca})" in log
    assert "set tls_ca_file to the CA certificate (PEM) that signed it" in log
    assert f"tls_ca_file {missing}: cannot read it" in absent.log()
    # the broker's "certificate required" alert, or a bare EOF before CONNACK when the alert is
    # lost: either way the hint names the keys to set
    assert "requires a client certificate" in no_certificate.log()
    assert "set tls_cert_file and tls_key_file" in no_certificate.log()


async def _wait_for_log(
    service: ServiceProcess, text: str, count: int = 1, within_s: float = 20
) -> None:
    async with asyncio.timeout(within_s):
        while service.log().count(text) < count:
            await asyncio.sleep(0.1)


@pytest.fixture
def shipped_config_broker(tmp_path: Path, pki: Pki) -> Iterator[tuple[int, int]]:
    """Mosquitto on config/mosquitto/mosquitto-secure.conf with its paths and ports moved into
    the test's directory and the files of make-credentials; yields (plain port, TLS port)."""
    binary = require_mosquitto()
    files = tmp_path / "vda"
    logins = ["--master", "vda-master:pw", "--vehicle", "vda-sim/robot_0:pw0"]
    subprocess.run(  # noqa: S603 - the repository's own script
        [str(REPO / "config/mosquitto/make-credentials"), "--out", str(files), *logins],
        check=True,
        capture_output=True,
    )
    for name, source in (("ca.pem", pki.ca), ("server.pem", pki.server_cert)):
        (files / name).write_bytes(source.read_bytes())
    (files / "server.key").write_bytes(pki.server_key.read_bytes())
    plain, tls = free_port(), free_port()
    text = (REPO / "config/mosquitto/mosquitto-secure.conf").read_text()
    text = text.replace("/etc/mosquitto/vda/", f"{files}/")
    text = text.replace("listener 1883 127.0.0.1", f"listener {plain} 127.0.0.1")
    text = text.replace("listener 8883 0.0.0.0", f"listener {tls} 127.0.0.1")
    if os.geteuid() == 0:
        text += "user root\n"
    config = tmp_path / "mosquitto.conf"
    config.write_text(text)
    log = tmp_path / "mosquitto.log"
    with log.open("ab") as sink:
        process = subprocess.Popen([binary, "-c", str(config)], stdout=sink, stderr=sink)  # noqa: S603
    try:
        wait_listening(BrokerAddress("127.0.0.1", tls), process, log)
        yield plain, tls
    finally:
        process.terminate()
        process.wait(5)


async def test_shipped_secure_config_loads_and_serves_logins_over_tls(
    shipped_config_broker: tuple[int, int], pki: Pki
) -> None:
    """The shipped mosquitto-secure.conf starts, accepts a make-credentials login over TLS and
    refuses anonymous clients."""
    plain, tls = shipped_config_broker
    context = ssl.create_default_context(cafile=str(pki.ca))
    login = {"username": "robot_0", "password": "pw0", "tls_context": context}
    async with aiomqtt.Client("127.0.0.1", tls, **login) as client:  # type: ignore[arg-type]
        await client.publish("uagv/v2/vda-sim/robot_0/connection", b"{}", qos=1)
    with pytest.raises(aiomqtt.MqttError):
        async with aiomqtt.Client("127.0.0.1", plain):
            pass
