"""Who sent what on the test's interface, checked against the official 2.0.0 schemas.

Every message is validated against ``official-schemas/2.0.0/<topic>.schema`` (the copy in
``_patched/2.0.0/`` where one exists). A problem in a message of OUR service fails the test: we
write spec-exact messages. A problem in a message of the PEER is compared with the list of known
peer deviations: a known one is recorded (the tests assert it where it matters), an unknown one
fails the test too, because either the peer changed or the harness misuses it.
"""

from __future__ import annotations

import functools
import json
from collections.abc import Iterable
from dataclasses import dataclass
from enum import StrEnum

from jsonschema import Draft202012Validator, FormatChecker

from tests.spec_files import OFFICIAL_SCHEMAS, official_schema
from tests.system.stack import Captured
from vda5050 import schemas
from vda5050.schemas import schema_file_name
from vda5050.topics import Topic
from vda_inspect.rules import Finding, Inspector

VERSION = "2.0.0"
#: Topics master control publishes; the vehicle publishes the others (§6.1).
MASTER_TOPICS = frozenset({"order", "instantActions"})


class Side(StrEnum):
    """Which side of the interface published a message."""

    MASTER = "master"
    VEHICLE = "vehicle"


@dataclass(frozen=True, slots=True)
class SchemaProblem:
    """One way in which one message breaks the official schema of its topic."""

    topic: str
    side: Side
    header_id: object
    text: str

    def __str__(self) -> str:
        return f"{self.topic} (headerId {self.header_id}, by the {self.side}): {self.text}"


@dataclass(frozen=True, slots=True)
class KnownDeviation:
    """A way in which the peer's messages are known to break the schema, and why."""

    topic: str
    fragment: str
    why: str

    def explains(self, problem: SchemaProblem) -> bool:
        return problem.topic.endswith("/" + self.topic) and self.fragment in problem.text


#: vda-5050-lib 1.4.0, VDA 5050 2.0.0.
LIB_DEVIATIONS = (
    KnownDeviation(
        "instantActions",
        "'actions' is a required property",
        "the MasterController sends the array under 'instantActions' (the 1.x name) in 2.0.0",
    ),
    KnownDeviation(
        "factsheet",
        "is a required property",
        "the virtual AGV has no factsheet: factsheetRequest publishes only the header",
    ),
)


def side_of(topic: str) -> Side:
    return Side.MASTER if topic.rsplit("/", 1)[-1] in MASTER_TOPICS else Side.VEHICLE


def schema_problems(captured: Captured) -> list[SchemaProblem]:
    """Every way in which a captured message breaks the official 2.0.0 schema of its topic."""
    problems: list[SchemaProblem] = []
    for message in captured.messages:
        topic = str(message.topic)
        side = side_of(topic)
        try:
            payload = json.loads(message.payload)
        except ValueError as exc:
            problems.append(SchemaProblem(topic, side, None, f"not JSON ({exc})"))
            continue
        header_id = payload.get("headerId") if isinstance(payload, dict) else None
        validator = _validator(topic.rsplit("/", 1)[-1])
        problems.extend(
            SchemaProblem(topic, side, header_id, f"{error.message} at {error.json_path}")
            for error in validator.iter_errors(payload)
        )
    return problems


@functools.cache
def _validator(kind: str) -> Draft202012Validator:
    """The official 2.0.0 schema of ``kind`` where the shared folder is present, else the
    project's own 2.0.0 schema (generated from the models, checked against the official ones
    by tests/unit/test_schemas.py whenever that folder is present)."""
    if not OFFICIAL_SCHEMAS.is_dir():
        return schemas.validator(schema_file_name(Topic(kind), VERSION))
    return Draft202012Validator(official_schema(VERSION, kind), format_checker=FormatChecker())


@dataclass(frozen=True, slots=True)
class Verdict:
    """Schema problems split by who is to blame."""

    ours: list[SchemaProblem]
    known_peer: list[SchemaProblem]
    unknown_peer: list[SchemaProblem]

    def failures(self) -> list[str]:
        lines = [f"OUR service broke the schema: {p}" for p in self.ours]
        lines += [f"the peer broke the schema in an unknown way: {p}" for p in self.unknown_peer]
        return lines


def judge(
    problems: Iterable[SchemaProblem], our_side: Side, known: Iterable[KnownDeviation]
) -> Verdict:
    """Split ``problems`` into ours, known peer deviations and unknown peer deviations."""
    known = tuple(known)
    ours, known_peer, unknown_peer = [], [], []
    for problem in problems:
        if problem.side is our_side:
            ours.append(problem)
        elif any(deviation.explains(problem) for deviation in known):
            known_peer.append(problem)
        else:
            unknown_peer.append(problem)
    return Verdict(ours, known_peer, unknown_peer)


def inspected(captured: Captured) -> list[Finding]:
    """What ``vda-inspect`` finds in the captured traffic (replayed with the arrival times;
    unanswered orders counted up to the last message)."""
    inspector = Inspector()
    found: list[Finding] = []
    for message, at in zip(captured.messages, captured.times, strict=True):
        payload = message.payload if isinstance(message.payload, bytes) else b""
        topic = str(message.topic)
        found += inspector.observe(topic, payload, qos=message.qos, retain=message.retain, now=at)
    if captured.times:
        found += inspector.tick(captured.times[-1])
    return found


def inspect_side(finding: Finding) -> Side:
    return Side.MASTER if finding.side == "master control" else Side.VEHICLE
