"""Hostile MQTT traffic for the flood test and the fault benchmark (issue 14).

Each generator yields (topic, payload) pairs aimed at one service's inbound topics: garbage,
schema-invalid and absurd messages, oversized ones, and (for the master) made-up vehicles.
Deterministic (seeded), so a failure can be replayed.
"""

from __future__ import annotations

import json
import random
from collections.abc import Iterator

from vda5050.codec import encode
from vda5050.testing import HEADER, make_action, make_instant_actions, make_order, make_state

Message = tuple[str, bytes]


def _header(serial: str) -> dict[str, object]:
    return {**{k: v for k, v in HEADER.items() if k != "header_id"}, "serialNumber": serial}


#: A state field and a value of the wrong type for it: each makes a state invalid.
_WRONG: tuple[tuple[str, object], ...] = (
    ("orderId", 5),
    ("nodeStates", "x"),
    ("driving", "yes"),
    ("batteryState", []),
    ("safetyState", -1),
    ("headerId", -1),
    ("operatingMode", "automatic"),
)


#: An order field and a value that makes the order invalid (schema or R21).
_BAD_ORDER: tuple[tuple[str, object], ...] = (
    ("nodes", []),
    ("nodes", "x"),
    ("edges", -5),
    ("orderUpdateId", -5),
    ("version", "9.9.9"),
    ("timestamp", "yesterday"),
)


def _deep(depth: int) -> bytes:
    return b"[" * depth + b"]" * depth


def at_master(prefix: str, serial: str, count: int, seed: int = 5050) -> Iterator[Message]:
    """``count`` messages on ``<prefix>/<serial>/{state,connection,factsheet}`` and on made-up
    vehicles' topics; ``prefix`` is ``<interface>/v2/<manufacturer>``."""
    rng = random.Random(seed)
    own = f"{prefix}/{serial}"
    state = json.loads(
        encode(make_state(manufacturer=prefix.rsplit("/", 1)[-1], serial_number=serial))
    )
    kinds = ["garbage", "wrong_types", "made_up", "nested", "factsheet", "nan", "huge"]
    weights = [25, 25, 20, 10, 10, 9, 1]
    for index in range(count):
        kind = rng.choices(kinds, weights)[0]
        if kind == "garbage":
            yield f"{own}/state", rng.randbytes(rng.randint(0, 200))
        elif kind == "wrong_types":
            key, value = rng.choice(_WRONG)
            yield f"{own}/state", json.dumps({**state, key: value}).encode()
        elif kind == "made_up":
            made_up = f"ghost-{index}"
            body = {**_header(made_up), "headerId": 0, "connectionState": "ONLINE"}
            body["manufacturer"] = prefix.rsplit("/", 1)[-1]
            yield f"{prefix}/{made_up}/connection", json.dumps(body).encode()
        elif kind == "nested":
            yield f"{own}/state", _deep(rng.randint(200, 5000))
        elif kind == "factsheet":
            yield f"{own}/factsheet", json.dumps({"headerId": "x", "typeSpecification": 1}).encode()
        elif kind == "nan":
            yield (
                f"{own}/state",
                json.dumps({**state, "batteryState": {"batteryCharge": float("nan")}}).encode(),
            )
        else:
            yield f"{own}/state", json.dumps({**state, "orderId": "x" * 400_000}).encode()


def at_vehicle(prefix: str, count: int, seed: int = 5051) -> Iterator[Message]:
    """``count`` messages on ``<prefix>/{order,instantActions}`` (``prefix`` is the vehicle's
    ``<interface>/v2/<manufacturer>/<serial>``)."""
    rng = random.Random(seed)
    manufacturer, serial = prefix.rsplit("/", 2)[-2:]
    base = make_order(["a", "b"], manufacturer=manufacturer, serial_number=serial)
    valid = json.loads(encode(base))
    kinds = ["garbage", "invalid_order", "absurd_order", "long_id", "many_actions", "unknown"]
    weights = [30, 30, 20, 2, 2, 16]
    for index in range(count):
        kind = rng.choices(kinds, weights)[0]
        if kind == "garbage":
            topic = rng.choice(["order", "instantActions"])
            yield f"{prefix}/{topic}", rng.randbytes(rng.randint(0, 200))
        elif kind == "invalid_order":
            key, value = rng.choice(_BAD_ORDER)
            broken = {**valid, "orderId": f"bad-{index}", key: value}
            yield f"{prefix}/order", json.dumps(broken).encode()
        elif kind == "absurd_order":
            absurd = make_order(
                ["a", "b"],
                order_id=f"absurd-{index}",
                positions=[(0.0, 0.0), (1e300, 0.0)],
                manufacturer=manufacturer,
                serial_number=serial,
            )
            yield f"{prefix}/order", encode(absurd)
        elif kind == "long_id":
            yield (
                f"{prefix}/order",
                encode(
                    make_order(
                        ["a"],
                        order_id="o" * 900_000,
                        manufacturer=manufacturer,
                        serial_number=serial,
                    )
                ),
            )
        elif kind == "many_actions":
            actions = [make_action("stateRequest", f"q{index}-{n}") for n in range(10_000)]
            many = make_instant_actions(*actions, manufacturer=manufacturer, serial_number=serial)
            yield f"{prefix}/instantActions", encode(many)
        else:
            yield (
                f"{prefix}/instantActions",
                encode(
                    make_instant_actions(
                        make_action("selfDestruct", f"u{index}"),
                        manufacturer=manufacturer,
                        serial_number=serial,
                    )
                ),
            )
