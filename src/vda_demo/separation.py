"""The demo's own observer of the robots' positions (``visualization`` over MQTT): the closest
two robots came to each other, measured outside master control."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import orjson

from vda5050.mqtt import InboundMessage


@dataclass
class Separation:
    """Latest position per robot and the closest approach seen."""

    positions: dict[str, tuple[float, float]] = field(default_factory=dict)
    minimum_m: float = math.inf
    pair: tuple[str, str] = ("", "")

    def see(self, serial: str, x: float, y: float) -> None:
        self.positions[serial] = (x, y)
        for other, (ox, oy) in self.positions.items():
            if other != serial:
                distance = math.hypot(x - ox, y - oy)
                if distance < self.minimum_m:
                    self.minimum_m, self.pair = distance, (serial, other)

    async def on_message(self, message: InboundMessage) -> None:
        """MqttSession handler for ``<interface>/v2/+/+/visualization``."""
        try:
            payload = orjson.loads(message.payload)
            position = payload["agvPosition"]
            self.see(message.topic.split("/")[3], float(position["x"]), float(position["y"]))
        except (orjson.JSONDecodeError, KeyError, TypeError, ValueError, IndexError):
            return

    def summary(self, safety_m: float | None) -> str:
        if not self.positions or math.isinf(self.minimum_m):
            return "closest approach: not measured"
        limit = f" (safety distance {safety_m:.2f} m)" if safety_m else ""
        return f"closest approach: {self.minimum_m:.2f} m, {self.pair[0]} and {self.pair[1]}{limit}"
