"""Master control settings (architecture §3.2, house style §3.8).

Every field is a config-file key, a command-line flag (generated from this model by
:mod:`vda5050.cli`) and an environment variable ``VDA_<KEY>``; precedence flag > environment >
config file > default (:func:`vda5050.config.load_settings`). Unknown keys fail at start-up.
Units are in the names; times are seconds.
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Literal
from urllib.parse import urlsplit

from pydantic import BaseModel, ConfigDict, Field, field_validator, model_validator

from vda5050.config import BrokerConnectionConfig, load_settings


class RobotRef(BaseModel):
    """A vehicle of the fleet, known before it first connects."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    manufacturer: Annotated[str, Field(min_length=1)]
    serial_number: Annotated[str, Field(min_length=1)]


class MasterConfig(BrokerConnectionConfig):
    """Settings of ``vda-master``. The broker keys (``broker_url``, ``username``, ``password``,
    ``client_id`` (default ``vda-master``), ``qos``, ``keepalive_s``, ``clean_session``,
    ``connect_timeout_s``) come from :class:`vda5050.config.BrokerConnectionConfig`."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    embedded_broker: bool = Field(
        default=False,
        description="start the amqtt broker in this process on the broker URL's host and port",
    )
    interface_name: Annotated[str, Field(min_length=1)] = Field(
        default="uagv", description="first topic level for 2.x vehicles (topics uagv/v2/...)"
    )
    interface_name_v3: Annotated[str, Field(min_length=1)] = Field(
        default="vda5050",
        description="first topic level for 3.x vehicles (topics vda5050/v3/..., 3.0 §4.2)",
    )
    graph: Path = Field(default=Path("config/graphs/demo.json"), description="the JSON graph file")
    api_host: str = Field(default="127.0.0.1", description="address the HTTP API listens on")
    api_port: Annotated[int, Field(ge=0, le=65535)] = Field(
        default=8050, description="port of the HTTP API (0: any free port)"
    )
    robots: list[RobotRef] = Field(
        default_factory=list,
        description="the fleet, listed before it connects: [{manufacturer, serial_number}, ...]",
    )
    log_level: Literal["DEBUG", "INFO", "WARNING", "ERROR"] = Field(
        default="INFO", description="log level"
    )
    log_json: bool | None = Field(
        default=None, description="JSON log lines (default: unless stderr is a terminal)"
    )
    release_window_nodes: Annotated[int, Field(ge=0)] = Field(
        default=3,
        description="released nodes kept ahead of each vehicle; the rest is horizon; 0 = all",
    )
    confirm_timeout_s: Annotated[float, Field(gt=0)] = Field(
        default=2.0, description="an order message no state confirms in this time is resent"
    )
    max_sends: Annotated[int, Field(ge=1)] = Field(
        default=4, description="sends of one order message in all before the order FAILS"
    )
    unreachable_after_intervals: Annotated[float, Field(gt=0)] = Field(
        default=3.0,
        description="silence, in state intervals (factsheet, else 30 s), that makes a vehicle "
        "unreachable",
    )
    tick_s: Annotated[float, Field(gt=0)] = Field(
        default=0.05, description="how often resends and delayed sends are checked"
    )
    traffic_control: bool = Field(
        default=True,
        description="coordinate the fleet: release a base only over free resources, plan "
        "around others, resolve deadlocks (docs/traffic.md)",
    )
    safety_distance_m: Annotated[float, Field(gt=0)] | None = Field(
        default=None,
        description="resources closer than this conflict (default: largest vehicle footprint "
        "diagonal from the factsheets + 0.25 m, else 1.0 m)",
    )
    zone_margin_m: Annotated[float, Field(ge=0)] = Field(
        default=0.0,
        description="how far beyond its polygon a zone reaches: an edge or node this close to a "
        "BLOCKED zone is closed, to a SPEED_LIMIT zone slowed (half the vehicles' width or "
        "diagonal keeps their bodies out; 0: the polygon is drawn round what the vehicles' "
        "reference points must keep out of)",
    )
    release_lease_s: Annotated[float, Field(ge=0)] = Field(
        default=60.0,
        description="how long a 3.0 robot's access to a RELEASE zone (or corridor) is granted "
        "before master control renews it (leaseExpiry; renewed at half time; 0: no lease)",
    )
    max_wait_s: Annotated[float, Field(gt=0)] = Field(
        default=30.0, description="a vehicle waiting this long in traffic gets a new route"
    )
    one_lane_cost_factor: Annotated[float, Field(ge=1)] = Field(
        default=4.0,
        description="with traffic control, routing counts a metre of one-lane edge (its "
        "opposite exists: aisles, spurs) as this many metres, so through traffic keeps to "
        "two-way corridors; 1 = plain shortest routes",
    )
    detour_margin_s: Annotated[float, Field(ge=0)] = Field(
        default=0.0,
        description="with traffic control, a route round other vehicles' expected passages is "
        "taken only if it is expected to arrive this many seconds before the cheapest route "
        "with its waits",
    )
    time_lapse: Annotated[float, Field(gt=0)] = Field(
        default=1.0,
        description="the vehicles are simulated this many times faster than real time (as "
        "vda-vehicle --time-lapse): traffic control's durations (max_wait_s, detour_margin_s, "
        "its plans' margins and expected stays, how often it looks for deadlocks) are simulated "
        "seconds and edges' maxSpeed simulated m/s; message timeouts stay wall time",
    )
    charge_below_pct: Annotated[float, Field(ge=0, le=100)] = Field(
        default=30.0,
        description="energy management: an idle vehicle whose batteryCharge falls under this "
        "is sent to the nearest free charging node to charge (startCharging); 0 = off",
    )
    charged_pct: Annotated[float, Field(gt=0, le=100)] = Field(
        default=80.0,
        description="energy management: a charging vehicle that runs no order is sent "
        "stopCharging at this batteryCharge and takes orders again",
    )
    accept_unlisted_vehicles: bool = Field(
        default=True,
        description="track every vehicle that publishes; false: only the robots list (others "
        "are logged once and ignored)",
    )
    forget_after_s: Annotated[float, Field(gt=0)] = Field(
        default=600.0,
        description="a vehicle not in the robots list that is silent this long (OFFLINE, gone, "
        "or never more than ONLINE) leaves the live view",
    )
    max_message_bytes: Annotated[int, Field(ge=1024)] = Field(
        default=262_144,
        description="largest vehicle message folded into the view; larger ones are dropped",
    )
    api_operator_keys: list[str] = Field(
        default_factory=list,
        description="API keys that may read and act (orders, cancels, instant actions); a "
        "comma-separated string is accepted too",
    )
    api_viewer_keys: list[str] = Field(
        default_factory=list, description="API keys that may only read"
    )
    insecure_api: bool = Field(
        default=False,
        description="allow an HTTP API without keys on a non-loopback address",
    )
    max_body_bytes: Annotated[int, Field(ge=1024)] = Field(
        default=1_048_576, description="largest HTTP request body; larger ones get 413"
    )
    max_map_bytes: Annotated[int, Field(ge=1024)] = Field(
        default=64 * 1024 * 1024,
        description="largest map file PUT /maps/{mapId}/{mapVersion} takes; larger ones get 413",
    )
    public_url: str | None = Field(
        default=None,
        description="the HTTP API's address as vehicles reach it, for the map download links "
        "of downloadMap (default: http://<api_host>:<port>, unless api_host is a wildcard)",
    )
    webhook_urls: list[str] = Field(
        default_factory=list,
        description="where order status events and vehicle connection, error and safety "
        "events are POSTed (JSON); kept in the store until delivered; a comma-separated string "
        "is accepted too",
    )
    webhook_secret: str | None = Field(
        default=None,
        description="signs every webhook request: X-VDA-Signature: sha256=<HMAC-SHA256 of the "
        "body>",
    )
    webhook_max_attempts: Annotated[int, Field(ge=0)] = Field(
        default=10,
        description="attempts per webhook event (waits doubling from 0.5 s to 30 s between "
        "them) before it is dropped and logged; 0: until delivered (a receiver's later events "
        "wait behind it, 10,000 at most)",
    )
    data_dir: Path = Field(
        default=Path("var"),
        description="where the SQLite store (master.sqlite3) and the map files (maps/) live; "
        "created on start",
    )
    database_url: str | None = Field(
        default=None,
        description="the store: postgresql://user:password@host:port/database, or "
        "sqlite:///file.sqlite3 (default: SQLite in data_dir)",
    )
    order_retention_days: Annotated[float, Field(gt=0)] = Field(
        default=30.0, description="ended orders older than this are pruned from the store"
    )
    recovery_timeout_s: Annotated[float, Field(gt=0)] = Field(
        default=60.0,
        description="after a restart, an open order whose vehicle has not reported for this "
        "long becomes UNKNOWN (its next state settles it)",
    )
    legacy_instant_actions_key: bool = Field(
        default=True,
        description="to 2.0.0 vehicles, also write the instantActions array under "
        "'instantActions' (what vda-5050-lib 1.4 reads); schema-valid either way",
    )

    @model_validator(mode="after")
    def _charge_band(self) -> MasterConfig:
        if self.charge_below_pct and self.charged_pct <= self.charge_below_pct:
            msg = (
                f"charged_pct ({self.charged_pct:g}) must be above charge_below_pct "
                f"({self.charge_below_pct:g}), or a charge would end before it began"
            )
            raise ValueError(msg)
        return self

    @field_validator("api_operator_keys", "api_viewer_keys", "webhook_urls", mode="before")
    @classmethod
    def _split_keys(cls, value: object) -> object:
        """``VDA_API_OPERATOR_KEYS=k1,k2`` (or ``VDA_WEBHOOK_URLS=u1,u2``) as well as a
        YAML/JSON list."""
        if isinstance(value, str):
            return [part.strip() for part in value.split(",") if part.strip()]
        return value

    @field_validator("webhook_urls")
    @classmethod
    def _webhook_urls(cls, urls: list[str]) -> list[str]:
        """Absolute http(s) URLs: a typo fails at start, not at the first event."""
        for url in urls:
            parts = urlsplit(url)
            if parts.scheme not in {"http", "https"} or not parts.hostname:
                msg = f"webhook URL {url!r} is not an absolute http:// or https:// URL"
                raise ValueError(msg)
        return urls


def load_master_config(
    config_path: Path | None, cli: dict[str, object], environ: dict[str, str] | None = None
) -> MasterConfig:
    """Flags > ``VDA_*`` environment > YAML file > defaults."""
    return load_settings(MasterConfig, config_path=config_path, cli=cli, environ=environ)


def interface_name(config: MasterConfig, major: int) -> str:
    """The first topic level of vehicles speaking ``major`` (2.x and 3.x are configured
    separately: ``interface_name``, ``interface_name_v3``)."""
    return config.interface_name_v3 if major == 3 else config.interface_name  # noqa: PLR2004
