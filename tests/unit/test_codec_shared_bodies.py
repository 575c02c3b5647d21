"""SharedBodies: a factsheet body alike across a fleet is validated once, and every message is
still decoded exactly as decode_as would (header checks R17/R18 included)."""

from __future__ import annotations

import orjson

from vda5050.codec import DecodeFailure, SharedBodies, decode_as, encode
from vda5050.models import Factsheet, v3
from vda5050.testing import make_factsheet_v3
from vda5050.topics import AgvId, Topic, TopicAddress
from vda_master.testing import make_factsheet


def _address(serial: str, major: int = 2) -> TopicAddress:
    return TopicAddress("uagv", major, AgvId("acme", serial), Topic.FACTSHEET)


def _factsheet(serial: str, **changes: object) -> bytes:
    raw = orjson.loads(encode(make_factsheet(serial_number=serial, header_id=3)))
    raw.update(changes)
    return orjson.dumps(raw)


def _both(payload: bytes, address: TopicAddress) -> tuple[object, object]:
    """What a warm cache answers, and what decode_as answers."""
    bodies = SharedBodies(Factsheet)
    bodies.decode(Topic.FACTSHEET, _factsheet("warm"), address=_address("warm"))
    assert len(bodies) == 1
    return (
        bodies.decode(Topic.FACTSHEET, payload, address=address),
        decode_as(Factsheet, Topic.FACTSHEET, payload, address=address),
    )


def test_a_body_seen_before_is_shared_and_the_header_is_the_messages_own() -> None:
    """The second vehicle's factsheet equals its full decode and shares the first one's parts."""
    bodies = SharedBodies(Factsheet)
    first = bodies.decode(Topic.FACTSHEET, _factsheet("r1"), address=_address("r1"))
    payload = _factsheet("r2", headerId=9, timestamp="2026-02-03T04:05:06.789Z")
    second = bodies.decode(Topic.FACTSHEET, payload, address=_address("r2"))
    assert isinstance(first, Factsheet)
    assert isinstance(second, Factsheet)
    assert second == decode_as(Factsheet, Topic.FACTSHEET, payload, address=_address("r2"))
    assert (second.serial_number, second.header_id) == ("r2", 9)
    assert second.physical_parameters is first.physical_parameters
    assert len(bodies) == 1


def test_key_order_and_spacing_do_not_matter() -> None:
    """The body is compared as parsed JSON: another sender's key order is the same body."""
    raw = orjson.loads(_factsheet("r2"))
    reordered = orjson.dumps(dict(reversed(list(raw.items()))), option=orjson.OPT_INDENT_2)
    cached, fresh = _both(reordered, _address("r2"))
    assert cached == fresh
    assert isinstance(cached, Factsheet)


def test_a_bad_header_on_a_known_body_fails_as_decode_as_fails() -> None:
    """An invalid headerId or timestamp is found although the body is known."""
    for change in ({"headerId": -1}, {"timestamp": "yesterday"}, {"headerId": "7"}):
        cached, fresh = _both(_factsheet("r2", **change), _address("r2"))
        assert isinstance(cached, DecodeFailure)
        assert isinstance(fresh, DecodeFailure)
        assert cached.problems == fresh.problems


def test_a_header_that_does_not_match_the_topic_fails_as_decode_as_fails() -> None:
    """R17/R18 on a known body: serialNumber of another vehicle, version of another major."""
    for change in ({"serialNumber": "someone"}, {"version": "3.0.0"}):
        cached, fresh = _both(_factsheet("r2", **change), _address("r2"))
        assert isinstance(cached, DecodeFailure)
        assert isinstance(fresh, DecodeFailure)
        assert cached.problems == fresh.problems


def test_a_missing_lenient_header_field_stays_missing() -> None:
    """2.x factsheet headers are optional: a field left out is None, not the cached one's."""
    raw = orjson.loads(_factsheet("r2"))
    del raw["headerId"], raw["timestamp"]
    cached, fresh = _both(orjson.dumps(raw), _address("r2"))
    assert cached == fresh
    assert isinstance(cached, Factsheet)
    assert cached.header_id is None


def test_invalid_or_unparsable_payloads_are_decode_as_failures_and_not_kept() -> None:
    """A body that fails validation is reported as decode_as reports it and never cached."""
    bodies = SharedBodies(Factsheet)
    bad_body = _factsheet("r1", physicalParameters={"speedMax": "fast"})
    for payload in (bad_body, b"not json", b"[1, 2]", b'{"headerId": 1}'):
        cached = bodies.decode(Topic.FACTSHEET, payload, address=_address("r1"))
        fresh = decode_as(Factsheet, Topic.FACTSHEET, payload, address=_address("r1"))
        assert isinstance(cached, DecodeFailure)
        assert isinstance(fresh, DecodeFailure)
        assert cached.problems == fresh.problems
    assert len(bodies) == 0


def test_oversized_payload_is_refused_before_parsing() -> None:
    """max_bytes holds for the cache as for decode_as."""
    bodies = SharedBodies(Factsheet)
    result = bodies.decode(Topic.FACTSHEET, _factsheet("r1"), address=_address("r1"), max_bytes=100)
    assert isinstance(result, DecodeFailure)
    assert "over the 100 limit" in result.summary()


def test_distinct_bodies_are_kept_up_to_the_limit() -> None:
    """Each distinct body is validated once; beyond ``limit`` the oldest is forgotten."""
    bodies = SharedBodies(Factsheet, limit=2)
    for speed in (1.0, 2.0, 3.0):
        raw = orjson.loads(_factsheet("r1"))
        raw["physicalParameters"]["speedMax"] = speed
        decoded = bodies.decode(Topic.FACTSHEET, orjson.dumps(raw), address=_address("r1"))
        assert isinstance(decoded, Factsheet)
        assert decoded.physical_parameters.speed_max == speed
    assert len(bodies) == 2


def test_v3_factsheets_are_shared_too() -> None:
    """A 3.0 factsheet (required header) goes the same way."""
    bodies = SharedBodies(v3.Factsheet)
    decoded = []
    for serial in ("r1", "r2"):
        payload = encode(make_factsheet_v3(serial_number=serial))
        decoded.append(bodies.decode(Topic.FACTSHEET, payload, address=_address(serial, 3)))
        fresh = decode_as(v3.Factsheet, Topic.FACTSHEET, payload, address=_address(serial, 3))
        assert decoded[-1] == fresh
    assert len(bodies) == 1


def _with_tail(serial: str, header_id: int, tail: bytes) -> bytes:
    """Our own encoding of a factsheet (header first), with ``tail`` added as its last keys."""
    payload = encode(make_factsheet(serial_number=serial, header_id=header_id))
    return payload[:-1] + tail + b"}"


def test_a_header_key_repeated_after_the_body_decodes_as_decode_as() -> None:
    """R17/R18 on shared bodies: JSON lets a later duplicate key win, so a body that repeats a
    header key (plainly or spelled with unicode escapes) must not lend the first vehicle's
    value to the next."""
    tails = (
        b',"headerId":77',
        b',"serialNumber":"r1"',
        b',"\\u0073erialNumber":"r1"',
        b',"\\u0068eaderId":77',
    )
    for tail in tails:
        bodies = SharedBodies(Factsheet)
        for serial, header_id in (("r1", 1), ("r2", 2)):
            payload = _with_tail(serial, header_id, tail)
            cached = bodies.decode(Topic.FACTSHEET, payload, address=_address(serial))
            fresh = decode_as(Factsheet, Topic.FACTSHEET, payload, address=_address(serial))
            assert cached == fresh, tail
            if isinstance(fresh, DecodeFailure):
                assert isinstance(cached, DecodeFailure)
                assert cached.problems == fresh.problems
        assert len(bodies) == 0, tail  # such a body is decoded in full each time


def test_our_own_encoding_is_shared_byte_for_byte_and_checked_like_any() -> None:
    """A fleet of ours sends the same body bytes after each header: shared, every header still
    validated as decode_as validates it (R16 a bad timestamp, R18 another vehicle's serial)."""
    bodies = SharedBodies(Factsheet)
    first = bodies.decode(Topic.FACTSHEET, _with_tail("r1", 1, b""), address=_address("r1"))
    assert isinstance(first, Factsheet)
    good = _with_tail("r2", 5, b"")
    bad_time = good.replace(b'"timestamp":"', b'"timestamp":"x', 1)
    for payload, address in ((good, "r2"), (bad_time, "r2"), (good, "r3")):
        cached = bodies.decode(Topic.FACTSHEET, payload, address=_address(address))
        fresh = decode_as(Factsheet, Topic.FACTSHEET, payload, address=_address(address))
        assert cached == fresh
        if isinstance(fresh, Factsheet):
            assert isinstance(cached, Factsheet)
            assert cached.physical_parameters is first.physical_parameters
            assert (cached.serial_number, cached.header_id) == ("r2", 5)
        else:
            assert isinstance(cached, DecodeFailure)
            assert cached.problems == fresh.problems
    assert len(bodies) == 1
