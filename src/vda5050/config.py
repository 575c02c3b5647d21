"""Layered configuration shared by both services (architecture §3.2, house style §3.8).

Precedence, highest first: command-line flag > environment variable ``VDA_<FLAG>`` > YAML
config file > the model's default. A flag ``--broker-url`` is the config key ``broker_url`` and
the environment variable ``VDA_BROKER_URL``. The models use ``extra="forbid"``, so a typo in a
config file fails at start-up with a message naming the key and the file.
"""

from __future__ import annotations

import argparse
import os
from collections.abc import Mapping
from pathlib import Path
from typing import Annotated, TypeVar

import yaml
from pydantic import BaseModel, ConfigDict, Field, ValidationError

from vda5050.cli import add_settings_flags, parse_structured, structured_fields
from vda5050.errors import ConfigError
from vda5050.mqtt import BrokerEndpoint, MqttSettings

T = TypeVar("T", bound=BaseModel)


class BrokerConnectionConfig(BaseModel):
    """How a service connects to the MQTT broker; shared keys of both services' config files.

    Publications always use the QoS and retain flag VDA 5050 fixes per topic (digest §1.3);
    ``qos`` is the QoS of the service's own subscriptions.
    """

    model_config = ConfigDict(extra="forbid", frozen=True)

    broker_url: str = Field(
        default="mqtt://127.0.0.1:1883",
        description="mqtt://[user:password@]host:port, or mqtts://... for TLS",
    )
    username: str | None = Field(
        default=None, description="broker login; wins over a user in the URL"
    )
    password: str | None = Field(
        default=None, description="broker password; wins over a password in the URL"
    )
    client_id: str | None = Field(
        default=None,
        description="MQTT client id, unique per broker (default: from the service's identity)",
    )
    qos: Annotated[int, Field(ge=0, le=2)] = Field(
        default=0,
        description="QoS of the subscriptions; a topic whose own QoS is higher keeps its own",
    )
    keepalive_s: Annotated[int, Field(ge=1, le=65535)] = Field(
        default=15,
        description="MQTT keep-alive, s; the broker declares the client dead after ~1.5x (§6.14)",
    )
    clean_session: bool = Field(
        default=True, description="MQTT clean session (persistent sessions need a client_id)"
    )
    connect_timeout_s: Annotated[float, Field(gt=0)] = Field(
        default=5.0, description="seconds to wait for the broker's CONNACK before retrying"
    )
    reconnect_max_s: Annotated[float, Field(gt=0)] = Field(
        default=5.0,
        description="longest wait between two connection attempts (jittered, doubling from "
        "0.1 s): a broker that is back is found within this",
    )
    tls_ca_file: Path | None = Field(
        default=None,
        description="mqtts://: PEM file of the CA that signed the broker's certificate (default: "
        "the system's trust store)",
    )
    tls_cert_file: Path | None = Field(
        default=None, description="mqtts://: client certificate (PEM) for mutual TLS"
    )
    tls_key_file: Path | None = Field(
        default=None, description="mqtts://: the unencrypted private key (PEM) of tls_cert_file"
    )
    publish_check_s: Annotated[float, Field(gt=0)] = Field(
        default=3.0,
        description="the service's own messages must come back from the broker within this "
        "time, else ERROR mqtt.publish_denied (ACL)",
    )

    def mqtt_settings(self, client_id: str | None = None) -> MqttSettings:
        """Session settings; ``client_id`` is used when the config sets none. ConfigError on a
        malformed broker URL."""
        endpoint = BrokerEndpoint.from_url(self.broker_url)
        return MqttSettings(
            url=self.broker_url,
            username=self.username if self.username is not None else endpoint.username,
            password=self.password if self.password is not None else endpoint.password,
            client_id=self.client_id or client_id,
            keepalive_s=self.keepalive_s,
            clean_session=self.clean_session,
            connect_timeout_s=self.connect_timeout_s,
            reconnect_max_s=self.reconnect_max_s,
            tls_ca_file=self.tls_ca_file,
            tls_cert_file=self.tls_cert_file,
            tls_key_file=self.tls_key_file,
            publish_check_s=self.publish_check_s,
        )


def read_yaml_mapping(path: Path) -> dict[str, object]:
    """Read a YAML file whose top level is a mapping; ConfigError otherwise."""
    try:
        loaded = yaml.safe_load(path.read_text(encoding="utf-8"))
    except OSError as exc:
        msg = f"cannot read config file {path}: {exc.strerror or exc}"
        raise ConfigError(msg) from None
    except yaml.YAMLError as exc:
        msg = f"config file {path} is not valid YAML: {exc}"
        raise ConfigError(msg) from None
    if loaded is None:
        return {}
    if not isinstance(loaded, dict):
        msg = f"config file {path} must hold a mapping of keys to values"
        raise ConfigError(msg)
    return {str(key): value for key, value in loaded.items()}


def environment_values(
    model: type[BaseModel], prefix: str, environ: Mapping[str, str]
) -> dict[str, object]:
    """Values of the model's top-level fields found as ``<prefix><FIELD>`` variables; lists and
    mappings are given as JSON or YAML text."""
    structured = structured_fields(model)
    found: dict[str, object] = {}
    for name in model.model_fields:
        value = environ.get(f"{prefix}{name.upper()}")
        if value is not None and value != "":
            found[name] = parse_structured(value) if name in structured else value
    return found


def load_settings(
    model: type[T],
    *,
    config_path: Path | None = None,
    cli: Mapping[str, object] | None = None,
    env_prefix: str = "VDA_",
    environ: Mapping[str, str] | None = None,
) -> T:
    """Build ``model`` from defaults, the config file, the environment and flags, in that order.

    ``cli`` holds the flags given on the command line; None values mean "not given".
    """
    layers: dict[str, object] = {}
    source = "defaults"
    if config_path is not None:
        layers.update(read_yaml_mapping(config_path))
        source = str(config_path)
    layers.update(environment_values(model, env_prefix, os.environ if environ is None else environ))
    layers.update({key: value for key, value in (cli or {}).items() if value is not None})
    try:
        return model.model_validate(layers)
    except ValidationError as exc:
        problems = "; ".join(
            f"{'.'.join(str(part) for part in error['loc']) or '<root>'}: {error['msg']}"
            for error in exc.errors(include_url=False)
        )
        msg = f"invalid configuration (from {source}, environment and flags): {problems}"
        raise ConfigError(msg) from None


def settings_parser(prog: str, description: str, model: type[BaseModel]) -> argparse.ArgumentParser:
    """``--config FILE`` plus one flag per field of ``model`` (architecture §3.2); unset flags
    stay None so the lower layers fill them."""
    parser = argparse.ArgumentParser(prog=prog, description=description)
    parser.add_argument("--config", type=Path, help="YAML config file (env VDA_CONFIG)")
    add_settings_flags(parser, model)
    return parser


def settings_from_command_line(
    parser: argparse.ArgumentParser,
    model: type[T],
    argv: list[str] | None,
    environ: Mapping[str, str] | None = None,
) -> T:
    """Flags > ``VDA_*`` environment > the YAML file of ``--config`` (or ``VDA_CONFIG``) >
    defaults; ``environ`` defaults to the process's."""
    args = vars(parser.parse_args(argv))
    env = dict(os.environ) if environ is None else environ
    config_path = args.pop("config") or (Path(env["VDA_CONFIG"]) if env.get("VDA_CONFIG") else None)
    return load_settings(model, config_path=config_path, cli=args, environ=env)
