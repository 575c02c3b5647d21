"""Layered configuration: flag > environment > config file > default (architecture §3.2)."""

from __future__ import annotations

from pathlib import Path

import pytest
from pydantic import BaseModel, ConfigDict

from vda5050.config import load_settings
from vda5050.errors import ConfigError
from vda_master.config import MasterConfig
from vda_vehicle.config import VehicleSettings


class Sample(BaseModel):
    model_config = ConfigDict(extra="forbid")

    broker_url: str = "mqtt://127.0.0.1:1883"
    keepalive_s: int = 15
    time_lapse: float = 1.0


def write(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "config.yaml"
    path.write_text(text)
    return path


def test_defaults_apply_without_any_source() -> None:
    """With no file, environment or flags, the model's defaults are used."""
    assert load_settings(Sample, environ={}) == Sample()


def test_precedence_is_flag_then_environment_then_file(tmp_path: Path) -> None:
    """A flag beats VDA_<FLAG>, which beats the config file, which beats the default."""
    path = write(tmp_path, "broker_url: mqtt://file:1\nkeepalive_s: 30\ntime_lapse: 2\n")
    environ = {"VDA_BROKER_URL": "mqtt://env:2", "VDA_KEEPALIVE_S": "20"}
    settings = load_settings(
        Sample,
        config_path=path,
        environ=environ,
        cli={"broker_url": "mqtt://flag:3", "keepalive_s": None},
    )
    assert settings == Sample(broker_url="mqtt://flag:3", keepalive_s=20, time_lapse=2.0)


def test_unknown_key_in_file_fails_naming_it(tmp_path: Path) -> None:
    """A typo in the config file fails at start-up with the key and the file named."""
    path = write(tmp_path, "brokr_url: x\n")
    with pytest.raises(ConfigError, match=r"brokr_url.*") as caught:
        load_settings(Sample, config_path=path, environ={})
    assert str(path) in str(caught.value)


@pytest.mark.parametrize(
    ("text", "fragment"),
    [("- a\n- b\n", "must hold a mapping"), ("a: [\n", "not valid YAML")],
)
def test_malformed_files_fail_clearly(tmp_path: Path, text: str, fragment: str) -> None:
    """A config file that is not a YAML mapping is refused with the reason."""
    with pytest.raises(ConfigError, match=fragment):
        load_settings(Sample, config_path=write(tmp_path, text), environ={})


def test_missing_file_fails_clearly(tmp_path: Path) -> None:
    """A config path that does not exist is refused, naming the path."""
    with pytest.raises(ConfigError, match="cannot read config file"):
        load_settings(Sample, config_path=tmp_path / "nope.yaml", environ={})


def test_bad_environment_value_fails_naming_the_field() -> None:
    """VDA_KEEPALIVE_S=abc is refused with the field name."""
    with pytest.raises(ConfigError, match="keepalive_s"):
        load_settings(Sample, environ={"VDA_KEEPALIVE_S": "abc"})


def test_broker_connection_defaults_follow_the_standard() -> None:
    """R12: the MQTT keep-alive defaults to about 15 s; explicit credentials win over the URL."""
    from vda5050.config import BrokerConnectionConfig  # noqa: PLC0415

    config = BrokerConnectionConfig(broker_url="mqtt://u:p@h:1", username="x", password="y")
    settings = config.mqtt_settings(client_id="default-id")
    assert settings.keepalive_s == 15
    assert (settings.endpoint.username, settings.endpoint.password) == ("x", "y")
    assert settings.client_id == "default-id"
    assert BrokerConnectionConfig().mqtt_settings().endpoint.username is None


def test_every_config_key_is_documented_in_the_readme() -> None:
    """The README's configuration reference names every key of both services."""
    readme = (Path(__file__).resolve().parents[2] / "README.md").read_text(encoding="utf-8")
    section = readme[readme.index("## Configuration reference") : readme.index("## HTTP API")]
    keys = {*MasterConfig.model_fields, *VehicleSettings.model_fields}
    missing = sorted(key for key in keys if f"`{key}`" not in section)
    assert missing == []
