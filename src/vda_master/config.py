"""Master control settings (architecture §3.2, house style §3.8).

Every command-line flag is also a config-file key and an environment variable ``VDA_<FLAG>``;
precedence flag > environment > config file > default (:func:`vda5050.config.load_settings`).
Unknown keys fail at start-up. Units are in the names; times are seconds.
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

from pydantic import BaseModel, ConfigDict, Field

from vda5050.config import BrokerConnectionConfig, load_settings


class RobotRef(BaseModel):
    """A vehicle of the fleet, known before it first connects."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    manufacturer: Annotated[str, Field(min_length=1)]
    serial_number: Annotated[str, Field(min_length=1)]


class MasterConfig(BrokerConnectionConfig):
    """Settings of ``vda-master``; each field documents its default. The broker keys
    (``broker_url``, ``username``, ``password``, ``client_id`` (default ``vda-master``), ``qos``,
    ``keepalive_s``, ``clean_session``, ``connect_timeout_s``) come from
    :class:`vda5050.config.BrokerConnectionConfig`."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    #: --embedded-broker: start the amqtt broker in this process on the broker URL's host/port.
    embedded_broker: bool = False
    #: --interface-name: first topic level (default ``uagv``).
    interface_name: Annotated[str, Field(min_length=1)] = "uagv"
    #: --graph: the JSON graph file (architecture §3.3).
    graph: Path = Path("config/graphs/demo.json")
    #: --api-host / --api-port: where the HTTP API listens (default 127.0.0.1:8050).
    api_host: str = "127.0.0.1"
    api_port: Annotated[int, Field(ge=0, le=65535)] = 8050
    #: The fleet: vehicles listed in the fleet view before they first connect (others are
    #: added when first heard from).
    robots: list[RobotRef] = Field(default_factory=list)
    #: Log level name and format (JSON lines unless stderr is a terminal, when None).
    log_level: str = "INFO"
    log_json: bool | None = None
    #: Released nodes kept ahead of each vehicle; 0 releases the whole route at once.
    release_window_nodes: Annotated[int, Field(ge=0)] = 3
    #: An order or update no state confirms within this time is sent again (QoS 0 may lose it).
    confirm_timeout_s: Annotated[float, Field(gt=0)] = 2.0
    #: Sends of one order message in all (first send + resends) before the order is FAILED.
    max_sends: Annotated[int, Field(ge=1)] = 4
    #: A vehicle silent for this many state intervals (factsheet, else 30 s) is unreachable.
    unreachable_after_intervals: Annotated[float, Field(gt=0)] = 3.0
    #: How often resend timeouts and minOrderInterval waits are checked.
    tick_s: Annotated[float, Field(gt=0)] = 0.05


def load_master_config(
    config_path: Path | None, cli: dict[str, object], environ: dict[str, str] | None = None
) -> MasterConfig:
    """Flags > ``VDA_*`` environment > YAML file > defaults."""
    return load_settings(MasterConfig, config_path=config_path, cli=cli, environ=environ)
