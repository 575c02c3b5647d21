"""vda-master settings: every flag of architecture §3.2, precedence flag > env > file > default."""

from __future__ import annotations

from pathlib import Path

import pytest

from vda5050.cli import flag_name, known_flags
from vda5050.errors import ConfigError
from vda_master.__main__ import build_parser, load_config
from vda_master.config import MasterConfig


def test_defaults_match_the_architecture() -> None:
    """Without flags, env or file: local broker, interface uagv, API on 127.0.0.1:8050."""
    config = load_config([], environ={})
    assert (config.broker_url, config.interface_name) == ("mqtt://127.0.0.1:1883", "uagv")
    assert (config.api_host, config.api_port, config.embedded_broker) == ("127.0.0.1", 8050, False)


def test_every_architecture_flag_exists() -> None:
    """All flags of §3.2 parse."""
    args = build_parser().parse_args(
        ["--config", "c.yaml", "--broker-url", "mqtt://h:1", "--embedded-broker",
         "--interface-name", "x", "--graph", "g.json", "--api-host", "localhost", "--api-port", "9"]
    )  # fmt: skip
    assert args.embedded_broker is True
    assert args.api_port == 9


def test_flag_beats_environment_beats_file(tmp_path: Path) -> None:
    """A flag wins over VDA_<FLAG>, which wins over the config file."""
    path = tmp_path / "master.yaml"
    path.write_text("broker_url: mqtt://file:1\ninterface_name: fromfile\napi_port: 1\n")
    env = {"VDA_BROKER_URL": "mqtt://env:2", "VDA_API_PORT": "2"}
    config = load_config(["--config", str(path), "--api-port", "3"], environ=env)
    assert (config.broker_url, config.interface_name, config.api_port) == (
        "mqtt://env:2",
        "fromfile",
        3,
    )


def test_config_path_from_environment(tmp_path: Path) -> None:
    """VDA_CONFIG names the config file when --config is not given."""
    path = tmp_path / "m.yaml"
    path.write_text("embedded_broker: true\n")
    assert load_config([], environ={"VDA_CONFIG": str(path)}).embedded_broker is True


def test_unknown_key_fails_at_startup(tmp_path: Path) -> None:
    """A typo in the config file is an error naming the key."""
    path = tmp_path / "m.yaml"
    path.write_text("brokr_url: mqtt://x:1\n")
    with pytest.raises(ConfigError, match="brokr_url"):
        load_config(["--config", str(path)], environ={})


def test_example_config_is_valid() -> None:
    """The shipped config/master.yaml loads."""
    example = Path(__file__).resolve().parents[3] / "config" / "master.yaml"
    config = load_config(["--config", str(example)], environ={})
    assert [r.serial_number for r in config.robots] == ["robot_0", "robot_1"]
    assert config.model_copy(update={"robots": [], "client_id": None}) == MasterConfig()


def test_every_config_key_is_a_flag() -> None:
    """The parser is generated from the settings model: every key has its flag (issue 8)."""
    flags = set(known_flags(build_parser()))
    assert {flag_name(key) for key in MasterConfig.model_fields} <= flags


def test_structured_keys_come_as_json_or_yaml_from_flags_and_environment() -> None:
    """--robots takes JSON/YAML text; VDA_ROBOTS too; booleans take --no-...."""
    config = load_config(
        ["--robots", "[{manufacturer: a, serial_number: r1}]", "--no-legacy-instant-actions-key"],
        environ={},
    )
    assert [(r.manufacturer, r.serial_number) for r in config.robots] == [("a", "r1")]
    assert config.legacy_instant_actions_key is False
    env = {"VDA_ROBOTS": '[{"manufacturer": "b", "serial_number": "r2"}]', "VDA_QOS": "1"}
    config = load_config([], environ=env)
    assert [r.serial_number for r in config.robots] == ["r2"]
    assert config.qos == 1
