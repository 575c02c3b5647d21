"""config/mosquitto/make-credentials: the ACL it writes gives each party exactly its topics."""

from __future__ import annotations

import importlib.machinery
import importlib.util
import stat
import sys
from pathlib import Path
from types import ModuleType

import pytest

from vda5050.topics import MASTER_TOPICS, V2_TOPICS, V3_TOPICS, VEHICLE_TOPICS

SCRIPT = Path(__file__).resolve().parents[2] / "config" / "mosquitto" / "make-credentials"


@pytest.fixture(scope="module")
def script() -> ModuleType:
    """The script, imported as a module (it has no .py suffix)."""
    loader = importlib.machinery.SourceFileLoader("make_credentials", str(SCRIPT))
    spec = importlib.util.spec_from_loader("make_credentials", loader)
    assert spec is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules["make_credentials"] = module  # dataclasses look their module up
    loader.exec_module(module)
    return module


def rules(acl: str) -> list[str]:
    return [line for line in acl.splitlines() if line and not line.startswith("#")]


def test_topic_lists_match_the_protocol_core(script: ModuleType) -> None:
    """The standalone script's topic lists agree with vda5050.topics for 2.x and 3.0."""
    for major, topics in ((2, V2_TOPICS), (3, V3_TOPICS)):
        assert set(script.MASTER_WRITES[major]) == {t.value for t in topics & MASTER_TOPICS}
    assert set(script.VEHICLE_WRITES) == {t.value for t in VEHICLE_TOPICS}


def test_acl_gives_master_and_vehicles_their_topics_only(script: ModuleType) -> None:
    """The master reads all vehicles and writes (reads back) commands; a vehicle pattern, per
    listed manufacturer, writes its own reports and reads its own commands; v3 adds zoneSet
    and responses on its own interface name."""
    acl = script.acl_text(
        masters=["boss"], observers=[], manufacturers=["acme"], interfaces={2: "uagv", 3: "vda"}
    )
    lines = rules(acl)
    master = lines[1 : lines.index("pattern readwrite uagv/v2/acme/%u/state")]
    assert lines[0] == "user boss"
    assert "topic read uagv/v2/+/+/state" in master
    assert "topic readwrite uagv/v2/+/+/order" in master
    assert "topic readwrite vda/v3/+/+/zoneSet" in master
    assert not [line for line in master if "write" in line and "/state" in line]
    vehicle = [line for line in lines if line.startswith("pattern")]
    assert "pattern write uagv/v2/acme/%u/visualization" in vehicle
    assert "pattern read uagv/v2/acme/%u/order" in vehicle
    assert "pattern read vda/v3/acme/%u/responses" in vehicle
    assert not [line for line in vehicle if "write" in line and "/order" in line]
    assert all("/acme/%u/" in line for line in vehicle)
    assert len(vehicle) == 6 + 8


def test_any_manufacturer_and_observers(script: ModuleType) -> None:
    """--any-manufacturer puts '+' on the manufacturer level; an observer only reads."""
    acl = script.acl_text(
        masters=["boss"], observers=["eye"], manufacturers=["+"], interfaces={2: "uagv"}
    )
    lines = rules(acl)
    eye = lines.index("user eye")
    assert lines[eye + 1] == "topic read uagv/v2/#"
    assert "pattern read uagv/v2/+/%u/instantActions" in lines
    assert not [line for line in lines if "/v3/" in line]


@pytest.mark.parametrize(
    ("argv", "fragment"),
    [
        (["--vehicle", "robot_0"], "expected MANUFACTURER/SERIAL"),
        (["--vehicle", "acme/robot 0"], "serial number may only contain"),
        (["--vehicle", "acme/r1", "--vehicle", "other/r1"], "usernames must be unique"),
        (["--majors", "2,4"], "only 2 and 3 exist"),
        (["--interface", "a/b"], "not one topic level"),
    ],
)
def test_bad_arguments_are_refused(
    script: ModuleType, tmp_path: Path, argv: list[str], fragment: str
) -> None:
    """Mistakes that would make a wrong or widened ACL stop the script with the reason."""
    with pytest.raises(script.UsageError, match=fragment):
        script.run(["--out", str(tmp_path), "--master", "boss", *argv])


def test_files_and_generated_passwords(script: ModuleType, tmp_path: Path) -> None:
    """Given passwords are kept, missing ones generated and listed in a 0600 file; the password
    file is handed to mosquitto_passwd -U (here a stand-in) and left 0640."""
    stand_in = tmp_path / "fake-passwd"
    stand_in.write_text("#!/bin/sh\nexit 0\n")
    stand_in.chmod(0o755)
    out = tmp_path / "out"
    argv = ["--out", str(out), "--master", "boss:given", "--vehicle", "acme/r1"]
    report = script.run([*argv, "--mosquitto-passwd", str(stand_in)])
    assert f"acl_file {(out / 'acl').resolve()}" in report
    lines = (out / "passwords").read_text().splitlines()
    assert lines[0] == "boss:given"
    (generated,) = (out / "credentials.txt").read_text().splitlines()
    user, password = generated.split()
    assert (user, lines[1]) == ("r1", f"r1:{password}")
    assert len(password) >= 20
    assert stat.S_IMODE((out / "credentials.txt").stat().st_mode) == 0o600
    assert stat.S_IMODE((out / "passwords").stat().st_mode) == 0o640
