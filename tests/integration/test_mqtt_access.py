"""MqttSession notices what the broker refuses: SUBACK 0x80 and publications that never come
back (issue 14, "denied operations are loud"), on the embedded broker and on Mosquitto."""

from __future__ import annotations

import asyncio
import signal
import subprocess
from dataclasses import replace
from pathlib import Path

import pytest
from structlog.testing import capture_logs

from tests.integration.test_mqtt_session import running, settings
from tests.mosquitto import DynsecClient, run_mosquitto
from vda5050.access import AccessKind, AccessProblem
from vda5050.broker import BrokerAddress
from vda5050.mqtt import InboundMessage, MqttSession
from vda5050.topics import Topic

REPO = Path(__file__).resolve().parents[2]
MAKE_CREDENTIALS = REPO / "config" / "mosquitto" / "make-credentials"


async def _ignore(_: InboundMessage) -> None:
    return None


async def _wait_for_problems(
    seen: list[tuple[AccessProblem, ...]], predicate: object, timeout: float = 5.0
) -> tuple[AccessProblem, ...]:
    assert callable(predicate)
    async with asyncio.timeout(timeout):
        while not (seen and predicate(seen[-1])):
            await asyncio.sleep(0.05)
    return seen[-1]


@pytest.mark.integration
async def test_own_publications_come_back_on_an_open_broker(
    embedded_broker: BrokerAddress, unique_interface_name: str
) -> None:
    """On an anonymous broker the echo check finds nothing wrong, for a topic published once
    per connect and one published often."""
    prefix = f"{unique_interface_name}/v2/acme/r1"
    seen: list[tuple[AccessProblem, ...]] = []
    base = replace(settings(embedded_broker), publish_check_s=0.5)
    session = MqttSession(base, on_access_changed=seen.append)
    session.verify_echo(f"{prefix}/connection")
    session.verify_echo(f"{prefix}/state")
    with capture_logs() as logs:
        async with running(session):
            session.publish(f"{prefix}/connection", Topic.CONNECTION, b"ONLINE")
            for index in range(5):
                session.publish(f"{prefix}/state", Topic.STATE, f"s{index}".encode())
                await asyncio.sleep(0.05)
            await asyncio.sleep(1.2)
            assert session.access_problems == ()
    assert seen == []
    assert not [e for e in logs if e["event"].startswith("mqtt.") and e["log_level"] == "error"]


def _credentials(directory: Path, *extra: str) -> Path:
    subprocess.run(  # noqa: S603 - the repository's own script
        [
            str(MAKE_CREDENTIALS),
            "--out",
            str(directory),
            "--master",
            "master:pw-master",
            "--vehicle",
            "acme/r1:pw-r1",
            *extra,
        ],
        check=True,
        capture_output=True,
    )
    return directory


@pytest.mark.mosquitto
async def test_publication_the_acl_drops_is_reported_until_the_acl_allows_it(
    tmp_path: Path, unique_interface_name: str
) -> None:
    """A vehicle whose ACL lacks write on its connection topic gets publish_denied (one ERROR,
    the hook); after the ACL is fixed and reloaded (SIGHUP) the next ONLINE clears it."""
    files = _credentials(tmp_path / "credentials", "--interface", unique_interface_name)
    acl = files / "acl"
    good = acl.read_text()
    connection = f"{unique_interface_name}/v2/acme/r1/connection"
    rule = f"pattern readwrite {unique_interface_name}/v2/acme/%u/connection"
    assert rule in good
    acl.write_text(good.replace(rule, rule.replace("readwrite", "read")))
    with run_mosquitto(
        tmp_path / "mosquitto", password_file=files / "passwords", acl_file=acl
    ) as broker:
        seen: list[tuple[AccessProblem, ...]] = []
        url = f"mqtt://r1:pw-r1@{broker.address.host}:{broker.address.port}"
        session = MqttSession(
            replace(settings(broker.address, url), publish_check_s=0.5),
            on_access_changed=seen.append,
            name="r1",
        )
        session.verify_echo(connection)
        with capture_logs() as logs:
            async with running(session):
                session.publish(connection, Topic.CONNECTION, b"ONLINE-1")
                problems = await _wait_for_problems(seen, bool)
                assert problems == (AccessProblem(AccessKind.PUBLISH_DENIED, connection),)
                acl.write_text(good)
                broker.process.send_signal(signal.SIGHUP)
                await asyncio.sleep(0.3)
                session.publish(connection, Topic.CONNECTION, b"ONLINE-2")
                await _wait_for_problems(seen, lambda p: p == ())
    denied = [e for e in logs if e["event"] == "mqtt.publish_denied"]
    assert len(denied) == 1
    assert denied[0]["topic"] == connection
    assert denied[0]["log_level"] == "error"
    assert "ACL" in denied[0]["hint"]
    assert [e["topic"] for e in logs if e["event"] == "mqtt.access_restored"] == [connection]


@pytest.mark.mosquitto
async def test_refused_subscription_is_reported(tmp_path: Path, unique_interface_name: str) -> None:
    """A SUBACK 0x80 (Mosquitto's dynamic-security plugin refuses the filter) is logged as ERROR
    mqtt.subscribe_denied naming the filter and the ACL, and passed to the hook; the granted
    filter of the same SUBSCRIBE is not reported."""
    prefix = f"{unique_interface_name}/v2/acme/r1"
    client = DynsecClient(
        "r1",
        "pw-r1",
        (
            ("subscribePattern", f"{prefix}/instantActions", True),
            ("publishClientSend", f"{prefix}/#", True),
        ),
    )
    with run_mosquitto(tmp_path, dynsec=[client]) as broker:
        seen: list[tuple[AccessProblem, ...]] = []
        url = f"mqtt://r1:pw-r1@{broker.address.host}:{broker.address.port}"
        session = MqttSession(settings(broker.address, url), on_access_changed=seen.append)
        session.subscribe(f"{prefix}/order", _ignore)
        session.subscribe(f"{prefix}/instantActions", _ignore)
        with capture_logs() as logs:
            async with running(session):
                problems = session.access_problems
    assert problems == (AccessProblem(AccessKind.SUBSCRIBE_DENIED, f"{prefix}/order"),)
    assert seen == [problems]
    (denied,) = [e for e in logs if e["event"] == "mqtt.subscribe_denied"]
    assert (denied["topic"], denied["log_level"]) == (f"{prefix}/order", "error")
    assert "ACL" in denied["hint"]
