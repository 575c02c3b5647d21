"""The fleet registry's factsheet documents: the body a fleet shares is dumped once, and every
vehicle's document is still exactly its own factsheet's JSON (header included)."""

from __future__ import annotations

import orjson

from vda5050.codec import SharedBodies, SharedBodyDumps, encode
from vda5050.models import Factsheet, v3
from vda5050.testing import make_factsheet_v3
from vda5050.topics import AgvId, Topic, TopicAddress
from vda_master.testing import make_factsheet


def _decoded(bodies: SharedBodies[Factsheet], serial: str, header_id: int) -> Factsheet:
    payload = encode(make_factsheet(serial_number=serial, header_id=header_id))
    address = TopicAddress("uagv", 2, AgvId("acme", serial), Topic.FACTSHEET)
    message = bodies.decode(Topic.FACTSHEET, payload, address=address)
    assert isinstance(message, Factsheet)
    return message


def _plain(message: Factsheet | v3.Factsheet) -> object:
    return message.model_dump(mode="json", by_alias=True, exclude_none=True)


def test_each_vehicles_document_is_its_own_factsheet_and_the_body_is_dumped_once() -> None:
    bodies = SharedBodies(Factsheet)
    dumps = SharedBodyDumps()
    first, second = _decoded(bodies, "r1", 3), _decoded(bodies, "r2", 9)
    one, two = dumps.dump(first), dumps.dump(second)
    assert one == _plain(first)
    assert two == _plain(second)
    assert (two["serialNumber"], two["headerId"]) == ("r2", 9)
    assert two["physicalParameters"] is one["physicalParameters"]  # dumped once, shared
    assert orjson.loads(orjson.dumps(two)) == _plain(second)


def test_factsheets_with_their_own_bodies_are_dumped_whole() -> None:
    """Equal content in distinct objects (decoded without SharedBodies), or another version's
    factsheet: each document is still the message's own."""
    dumps = SharedBodyDumps()
    a = make_factsheet(serial_number="a")
    b = make_factsheet(serial_number="b", min_order_interval=2.0)
    c = make_factsheet_v3(serial_number="c")
    for message in (a, b, c, a):
        assert dumps.dump(message) == _plain(message)


def test_the_memory_is_bounded() -> None:
    dumps = SharedBodyDumps(limit=2)
    messages = [make_factsheet(serial_number=f"r{i}", min_order_interval=1.0 + i) for i in range(5)]
    for message in messages:
        assert dumps.dump(message) == _plain(message)
    assert len(dumps) <= 2
