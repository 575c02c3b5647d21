"""A passive conformance check of VDA 5050 traffic on a broker (pure): every message seen on
``<interfaceName>/#`` is held against the rules a listener can judge, the digest's rule ids
named (docs/inspect.md). The shell is :mod:`vda5050.inspect`.

What a listener can judge, per message:

- R01: the topic has the five levels and a known last level;
- R03, R04, R05: the QoS it was published with (as delivered to a QoS 1 subscription: a broker
  delivers the lower of the publication's and the subscription's QoS; the embedded amqtt
  broker raises it instead, so ``check_qos`` must be off there);
- R14-R20 and the schema: the message decodes into its version's model (required fields,
  types, enums, the timestamp, ``version`` against the topic's ``v<major>``, the header's
  manufacturer and serialNumber against the topic's);
- R15: ``headerId`` goes up by exactly 1 per topic and sender. Going back or repeating is a
  violation (going back to 0 only a notice: a restarted sender); skipping ahead a notice
  (QoS 0 may lose messages on the way);
- R21-R26: an order's structure (sequenceIds, released prefix, edge endpoints, one action id
  once), master control's side; §6.6.6: its edge trajectories are NURBS from node to node
  (:mod:`vda_inspect.trajectory_rules`);
- R93 (and R27-R29, R79): every order and instant action is answered promptly by a state
  that carries it or an error naming it, and a factsheetRequest FINISHED by a factsheet (R80)
  (:mod:`vda_inspect.answers`);
- R97, R98, R99, R62, R55: a state that carries an order lists exactly its untraversed nodes
  and edges as the order gave them, keeps its orderId, lists nothing after a cancel and never
  reports a node of the horizon traversed (:mod:`vda_inspect.progress`); its action states
  and what ending actions leave behind (R60, R68-R78, R81, R87-R91:
  :mod:`vda_inspect.action_rules`, :mod:`vda_inspect.map_rules`);
- R56, R57, R58: master control's updates go up in orderUpdateId and stitch onto the decision
  point, resending it unchanged (:mod:`vda_inspect.updates`);
- R84: nothing is sent in an operating mode that forbids it (:mod:`vda_inspect.modes`);
- R92: a vehicle that is ONLINE publishes a state at least every 30 s (its factsheet's
  ``defaultStateInterval`` when it gives one);
- R112-R114: master control's orders and instant actions against the factsheet the vehicle
  published (:mod:`vda_inspect.factsheet_rules`);
- R94: two states of one vehicle are not stamped closer than its factsheet's
  ``minStateInterval`` (judged at half of it; by their own timestamps, which the listener's or
  the network's delays do not bunch as they may the receipt).

Retained messages (delivered with the retain flag when the subscription starts) are stale: they
are decoded and checked, but the live messages are not held against their headerIds; a vehicle
ONLINE again after OFFLINE or CONNECTIONBROKEN starts a new session whose headerIds may count
anew.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Iterable
from dataclasses import dataclass, field
from datetime import datetime
from typing import Final, Protocol

from vda5050.codec import DecodeFailure, decode
from vda5050.errors import TopicError
from vda5050.models import (
    Connection,
    ConnectionState,
    Factsheet,
    InstantActions,
    Order,
    State,
    v3,
)
from vda5050.models.v3.factsheet import Timing as Timing3
from vda5050.topics import Topic, TopicAddress, parse_topic
from vda5050.validation import check_order
from vda5050.validation3 import check_order as check_order_v3
from vda_inspect import modes
from vda_inspect.answers import OrderAnswers
from vda_inspect.factsheet_rules import (
    instant_actions_problems,
    min_order_interval_s,
    order_problems,
)
from vda_inspect.progress import OrderProgress
from vda_inspect.severity import Problem, Severity
from vda_inspect.trajectory_rules import trajectory_problems
from vda_inspect.updates import UpdateDiscipline
from vda_inspect.zone_rules import ZoneRequestWatch
from vda_master.wire3 import factsheet_from_v3

#: §6.2, §6.14: connection at QoS 1, every other topic at QoS 0 (R03-R05).
EXPECTED_QOS: Final = {topic: (1 if topic is Topic.CONNECTION else 0) for topic in Topic}
#: §6.10: a state at least this often without a factsheet's defaultStateInterval (R92).
STATE_INTERVAL_S: Final = 30.0
#: Slack on R92 for the network and the vehicle's timer.
STATE_SLACK_S: Final = 2.0
#: The rule each topic's QoS is held to; 3.0's zoneSet and responses are QoS 0 as well (3.0 §4.2).
_QOS_RULE: Final = {
    Topic.ORDER: "R03",
    Topic.INSTANT_ACTIONS: "R03",
    Topic.ZONE_SET: "R03",
    Topic.RESPONSES: "R03",
    Topic.STATE: "R04",
    Topic.VISUALIZATION: "R04",
    Topic.FACTSHEET: "R04",
    Topic.CONNECTION: "R05",
}
#: Topics master control (3.0: fleet control) publishes; the others are the vehicle's.
_FROM_MASTER: Final = frozenset(
    {Topic.ORDER, Topic.INSTANT_ACTIONS, Topic.ZONE_SET, Topic.RESPONSES}
)


@dataclass(frozen=True, slots=True)
class Finding:
    """One thing the traffic broke (or nearly did), with the rule it concerns."""

    rule: str
    severity: Severity
    #: ``manufacturer/serialNumber`` of the vehicle the topic names ("?" for a broken topic).
    vehicle: str
    #: The topic's last level, or the whole topic when it could not be read.
    topic: str
    #: Who published it: "vehicle" or "master control".
    side: str
    text: str


@dataclass(frozen=True, slots=True)
class InspectSettings:
    check_qos: bool = True
    #: An order not answered by a state within this long is R93 (:mod:`vda_inspect.answers`).
    answer_within_s: float = 2.0


@dataclass
class _Sender:
    """What is remembered of one vehicle (and of master control's messages to it)."""

    #: The last headerId per topic; the next one is compared with it (R15). Absent after a
    #: retained message and when a new session begins (a vehicle ONLINE again after OFFLINE or
    #: CONNECTIONBROKEN may be a restarted process, whose counters start anew).
    header_ids: dict[Topic, int] = field(default_factory=dict)
    counts: Counter[Topic] = field(default_factory=Counter)
    online: bool = False
    last_state_at: float | None = None
    #: The last state's own timestamp, in seconds since the epoch.
    last_state_stamp: float | None = None
    #: When R92 was last reported for the current silence (once per silence).
    overdue_reported: bool = False
    state_interval_s: float = STATE_INTERVAL_S
    min_state_interval_s: float = 0.0
    #: The vehicle's factsheet (a 3.0 one in its 2.x reading): what master control may send.
    factsheet: Factsheet | None = None
    #: The last order's own timestamp (minOrderInterval, R114).
    last_order_stamp: float | None = None
    #: Orders sent to the vehicle that no state has answered yet (R93).
    answers: OrderAnswers | None = None
    #: The orders it was sent, for what its states say about them (R97-R99, R62).
    progress: OrderProgress = field(default_factory=OrderProgress)
    #: The orders it was sent, for how master control updates them (R56-R58).
    updates: UpdateDiscipline = field(default_factory=UpdateDiscipline)
    #: The operating mode its live states report, and since when (R84).
    mode: str | None = None
    mode_since: float = 0.0
    #: A 3.0 robot's zone sets, zone requests and the answers to them (T91, T92).
    zones: ZoneRequestWatch | None = None


@dataclass
class Inspector:
    """Folds the messages seen into findings and a record per vehicle."""

    settings: InspectSettings = field(default_factory=InspectSettings)
    senders: dict[str, _Sender] = field(default_factory=dict)
    findings: Counter[tuple[str, str, str, str, Severity]] = field(default_factory=Counter)
    #: The first text of each (vehicle, topic, side, rule, severity), for the report.
    examples: dict[tuple[str, str, str, str, Severity], str] = field(default_factory=dict)
    messages: int = 0

    def observe(
        self, topic: str, payload: bytes, *, qos: int, retain: bool, now: float
    ) -> list[Finding]:
        """Judge one message; the findings it gives (also counted for :meth:`report`)."""
        self.messages += 1
        try:
            address = parse_topic(topic)
        except TopicError as exc:
            return self._record([Finding("R01", Severity.VIOLATION, "?", topic, "?", str(exc))])
        vehicle = f"{address.agv.manufacturer}/{address.agv.serial_number}"
        sender = self.senders.setdefault(vehicle, _Sender())
        sender.counts[address.topic] += 1
        side = "master control" if address.topic in _FROM_MASTER else "vehicle"
        found: list[Finding] = []

        def finding(rule: str, text: str, severity: Severity = Severity.VIOLATION) -> None:
            found.append(Finding(rule, severity, vehicle, address.topic.value, side, text))

        expected = EXPECTED_QOS[address.topic]
        if self.settings.check_qos and qos != expected:
            finding(_QOS_RULE[address.topic], f"published with QoS {qos}, not {expected}")
        message = decode(address.topic, payload, address=address)
        if isinstance(message, DecodeFailure):
            finding("R14-R20", f"not a valid {address.topic.value} message: {message.summary()}")
            if address.topic is Topic.FACTSHEET and sender.answers is not None and not retain:
                sender.answers.factsheet(now)  # it came (R80), if broken (R14-R20)
            return self._record(found)
        if (
            isinstance(message, Connection | v3.Connection)
            and _online(message)
            and not sender.online
        ):
            sender.header_ids.clear()  # a new session, perhaps a new process: counts anew
        if message.header_id is not None:
            self._header_id(sender, address, message.header_id, retain=retain, finding=finding)
        self._fold(sender, message, now=now, retain=retain, finding=finding)
        if isinstance(message, Order | v3.Order | InstantActions) and sender.factsheet is not None:
            self._against_factsheet(sender, message, len(payload), finding)
        return self._record(found)

    def _fold(
        self, sender: _Sender, message: object, *, now: float, retain: bool, finding: _Report
    ) -> None:
        """What each kind of message says beyond its header."""
        if isinstance(message, Order | v3.Order):
            for rule, problem in _order_problems(message):
                finding(rule, problem)
        if isinstance(message, Order | v3.Order | InstantActions | v3.InstantActions):
            if not retain:
                self._fold_sent(sender, message, now=now, finding=finding)
        elif isinstance(message, State | v3.State):
            self._fold_state(sender, message, now=now, retain=retain, finding=finding)
        elif isinstance(message, Connection | v3.Connection):
            _fold_connection(sender, message, now=now, retain=retain)
        elif isinstance(message, Factsheet | v3.Factsheet):
            _note_factsheet(sender, message)
            if sender.answers is not None and not retain:
                sender.answers.factsheet(now)
        elif isinstance(message, v3.ZoneSetMessage | v3.Responses) and not retain:
            self._fold_zones(sender, message, finding)

    def _fold_sent(
        self,
        sender: _Sender,
        message: Order | v3.Order | InstantActions | v3.InstantActions,
        *,
        now: float,
        finding: _Report,
    ) -> None:
        """A live order or instant actions master control sent: to be answered (R93), to
        judge the states by (R97-R99), and judged itself (R56-R58, R84)."""
        if sender.online:
            self._expect_answer(sender, message, now)
        _note_sent(sender.progress, message)
        for rule, text, severity in _sent_problems(sender, message, now):
            finding(rule, text, severity)

    def _fold_state(
        self,
        sender: _Sender,
        state: State | v3.State,
        *,
        now: float,
        retain: bool,
        finding: _Report,
    ) -> None:
        """R92, R94 by its timing; what it answers (R93); what it says of the order (R97-R99,
        R62), unless it is a stale retained one."""
        self._state_timing(sender, now, state.timestamp, retain=retain, finding=finding)
        if not retain and state.operating_mode.value != sender.mode:
            sender.mode, sender.mode_since = state.operating_mode.value, now
        if sender.answers is not None:
            sender.answers.state(state, now)
        if not retain:
            for rule, text, severity in sender.progress.state(state):
                finding(rule, text, severity)
        if isinstance(state, v3.State) and not retain:
            for rule, text in self._zones(sender).state(state, now):
                finding(rule, text)

    def _against_factsheet(
        self,
        sender: _Sender,
        message: Order | v3.Order | InstantActions,
        size: int,
        finding: _Report,
    ) -> None:
        """R112-R114: master control's message against the factsheet the vehicle published."""
        factsheet = sender.factsheet
        assert factsheet is not None  # noqa: S101 - checked by the caller
        if isinstance(message, InstantActions):
            for rule, text in instant_actions_problems(message, factsheet, size):
                finding(rule, text)
            return
        for rule, text in order_problems(message, factsheet, size):
            finding(rule, text)
        stamp, last = _seconds(message.timestamp), sender.last_order_stamp
        sender.last_order_stamp = stamp
        minimum = min_order_interval_s(factsheet)
        if stamp is not None and last is not None and 0 <= stamp - last < minimum / 2:
            finding(
                "R114",
                f"two orders stamped {(stamp - last) * 1000:.0f} ms apart (minOrderInterval "
                f"{minimum:g} s)",
            )

    def _expect_answer(
        self,
        sender: _Sender,
        message: Order | v3.Order | InstantActions | v3.InstantActions,
        now: float,
    ) -> None:
        """A state must answer this order or these instant actions (R93)."""
        answers = self._answers(sender)
        if isinstance(message, Order | v3.Order):
            answers.sent(message.order_id, message.order_update_id, now)
        else:
            answers.sent_actions([(a.action_id, a.action_type) for a in message.actions], now)

    def _fold_zones(
        self, sender: _Sender, message: v3.ZoneSetMessage | v3.Responses, finding: _Report
    ) -> None:
        """Zone sets master control sent, and its answers to zone requests (T92)."""
        zones = self._zones(sender)
        if isinstance(message, v3.ZoneSetMessage):
            zones.zone_set(message)
            return
        for rule, text in zones.responses(message):
            finding(rule, text)

    def _zones(self, sender: _Sender) -> ZoneRequestWatch:
        if sender.zones is None:
            sender.zones = ZoneRequestWatch(self.settings.answer_within_s)
        return sender.zones

    def _answers(self, sender: _Sender) -> OrderAnswers:
        if sender.answers is None:
            sender.answers = OrderAnswers(self.settings.answer_within_s)
        return sender.answers

    def tick(self, now: float) -> list[Finding]:
        """R92 for vehicles that are ONLINE and silent past their state interval (once per
        silence); R93 for orders no state answered in time."""
        found = []
        for vehicle, sender in self.senders.items():
            found.extend(_unanswered_actions(vehicle, sender, now))
            found.extend(_missing_factsheets(vehicle, sender, now))
            for rule, text in sender.zones.overdue(now) if sender.zones is not None else ():
                found.append(
                    Finding(rule, Severity.VIOLATION, vehicle, "responses", "master control", text)
                )
            for (order_id, update_id), waited in (
                sender.answers.overdue(now) if sender.answers is not None else ()
            ):
                text = (
                    f"no state carried order {order_id!r} update {update_id} or an error "
                    f"naming it within {waited:.1f} s of it"
                )
                found.append(_vehicle_violation("R93", vehicle, Topic.STATE, text))
            since = sender.last_state_at
            if not sender.online or since is None or sender.overdue_reported:
                continue
            if now - since > sender.state_interval_s + STATE_SLACK_S:
                sender.overdue_reported = True
                text = (
                    f"ONLINE but no state for {now - since:.1f} s (at most "
                    f"{sender.state_interval_s:g} s)"
                )
                found.append(_vehicle_violation("R92", vehicle, Topic.STATE, text))
        return self._record(found)

    def violations(self) -> int:
        return sum(n for key, n in self.findings.items() if key[4] is Severity.VIOLATION)

    def report(self) -> dict[str, object]:
        """Per vehicle: messages by topic, and each kind of finding with its count and first
        text (JSON-ready)."""
        vehicles: dict[str, object] = {}
        for vehicle, sender in sorted(self.senders.items()):
            vehicles[vehicle] = {
                "messages": {t.value: n for t, n in sorted(sender.counts.items())},
                "findings": [
                    {
                        "rule": rule,
                        "severity": severity.value,
                        "topic": topic,
                        "side": side,
                        "count": count,
                        "first": self.examples[(v, topic, side, rule, severity)],
                    }
                    for (v, topic, side, rule, severity), count in sorted(self.findings.items())
                    if v == vehicle
                ],
            }
        broken = [
            {"topic": topic, "count": count, "first": self.examples[(v, topic, s, r, sev)]}
            for (v, topic, s, r, sev), count in self.findings.items()
            if v == "?"
        ]
        return {
            "messages": self.messages,
            "violations": self.violations(),
            "vehicles": vehicles,
            "unreadableTopics": broken,
        }

    def _record(self, found: Iterable[Finding]) -> list[Finding]:
        out = list(found)
        for f in out:
            key = (f.vehicle, f.topic, f.side, f.rule, f.severity)
            self.findings[key] += 1
            self.examples.setdefault(key, f.text)
        return out

    def _header_id(
        self,
        sender: _Sender,
        address: TopicAddress,
        header_id: int,
        *,
        retain: bool,
        finding: _Report,
    ) -> None:
        last = sender.header_ids.get(address.topic)
        if retain:  # stale: it does not start the sequence the live messages continue
            sender.header_ids.pop(address.topic, None)
            return
        sender.header_ids[address.topic] = header_id
        if last is None:
            return
        if header_id == last:
            finding("R15", f"headerId {header_id} again")
        elif header_id < last:
            if header_id == 0:
                finding("R15", f"headerId back to 0 after {last} (restarted?)", Severity.NOTICE)
            else:
                finding("R15", f"headerId went back from {last} to {header_id}")
        elif header_id > last + 1:
            missing = header_id - last - 1
            finding("R15", f"{missing} headerId(s) skipped after {last} (lost?)", Severity.NOTICE)

    def _state_timing(
        self, sender: _Sender, now: float, stamp: str | None, *, retain: bool, finding: _Report
    ) -> None:
        """R92 by the time of receipt; R94 by the states' own timestamps (the receipt may bunch
        messages that were sent apart, when the listener or the network was busy)."""
        last, sender.last_state_at = sender.last_state_at, now
        last_stamp, sender.last_state_stamp = sender.last_state_stamp, _seconds(stamp)
        reported, sender.overdue_reported = sender.overdue_reported, False
        if retain or last is None:
            return
        gap = now - last
        if sender.online and not reported and gap > sender.state_interval_s + STATE_SLACK_S:
            finding(
                "R92", f"{gap:.1f} s between two states (at most {sender.state_interval_s:g} s)"
            )
        if last_stamp is None or sender.last_state_stamp is None:
            return
        apart = sender.last_state_stamp - last_stamp
        if 0 <= apart < sender.min_state_interval_s / 2:
            finding(
                "R94",
                f"two states stamped {apart * 1000:.0f} ms apart (minStateInterval "
                f"{sender.min_state_interval_s:g} s)",
            )


def _seconds(stamp: str | None) -> float | None:
    """An ISO 8601 timestamp as seconds since the epoch (None when absent or unreadable)."""
    if stamp is None:
        return None
    try:
        return datetime.fromisoformat(stamp.replace("z", "Z")).timestamp()
    except ValueError:
        return None


class _Report(Protocol):
    """The ``finding(rule, text, severity)`` callback of :meth:`Inspector.observe`."""

    def __call__(self, rule: str, text: str, severity: Severity = Severity.VIOLATION) -> None: ...


def _unanswered_actions(vehicle: str, sender: _Sender, now: float) -> list[Finding]:
    if sender.answers is None or not sender.answers.actions:
        return []
    return [
        _vehicle_violation(
            "R93",
            vehicle,
            Topic.STATE,
            f"no state showed instant action {action_type} {action_id!r} or an error naming it "
            f"within {waited:.1f} s of it",
        )
        for action_id, action_type, waited in sender.answers.overdue_actions(now)
    ]


def _vehicle_violation(rule: str, vehicle: str, topic: Topic, text: str) -> Finding:
    """A violation of ``vehicle``'s, found by the clock rather than in one of its messages."""
    return Finding(rule, Severity.VIOLATION, vehicle, topic.value, "vehicle", text)


def _fold_connection(
    sender: _Sender, message: Connection | v3.Connection, *, now: float, retain: bool
) -> None:
    online = _online(message)
    if online and not sender.online:
        sender.progress.new_session()
    sender.online = online
    if online and not retain:
        sender.last_state_at = now  # the heartbeat counts from the connect
    sender.overdue_reported = False


def _note_sent(
    progress: OrderProgress, message: Order | v3.Order | InstantActions | v3.InstantActions
) -> None:
    if isinstance(message, Order | v3.Order):
        progress.order(message)
    else:
        progress.instant_actions(message)


def _sent_problems(
    sender: _Sender,
    message: Order | v3.Order | InstantActions | v3.InstantActions,
    now: float,
) -> list[Problem]:
    """R56-R58 for an order or update; R84 for anything sent in a mode that forbids it."""
    held = now - sender.mode_since
    if isinstance(message, Order | v3.Order):
        found = sender.updates.sent(message)
        return found + modes.order_problems(sender.mode, held, v3=isinstance(message, v3.Order))
    types = [a.action_type for a in message.actions]
    return modes.instant_action_problems(
        sender.mode, held, types, v3=isinstance(message, v3.InstantActions)
    )


def _missing_factsheets(vehicle: str, sender: _Sender, now: float) -> list[Finding]:
    if sender.answers is None or not sender.answers.factsheet_due:
        return []
    return [
        _vehicle_violation(
            "R80",
            vehicle,
            Topic.FACTSHEET,
            f"factsheetRequest {action_id!r} FINISHED but no factsheet came within {waited:.1f} s",
        )
        for action_id, waited in sender.answers.missing_factsheets(now)
    ]


def _online(message: Connection | v3.Connection) -> bool:
    return message.connection_state.value == ConnectionState.ONLINE.value


def _order_problems(order: Order | v3.Order) -> list[tuple[str, str]]:
    """R21-R26 as a vehicle would check them (the first order of an id starts at 0), then its
    edge trajectories (§6.6.6)."""
    errors = check_order_v3(order) if isinstance(order, v3.Order) else check_order(order)
    found = [("R21-R26", e.error_description or e.error_type) for e in errors]
    return found + [("§6.6.6", problem) for problem in trajectory_problems(order)]


def _note_factsheet(sender: _Sender, factsheet: Factsheet | v3.Factsheet) -> None:
    try:
        sender.factsheet = (
            factsheet_from_v3(factsheet) if isinstance(factsheet, v3.Factsheet) else factsheet
        )
    except (ValueError, TypeError):
        sender.factsheet = None  # a 3.0 factsheet without a 2.x reading: R112-R114 unjudged
    timing = factsheet.protocol_limits.timing
    if isinstance(timing, Timing3):
        sender.min_state_interval_s = timing.minimum_state_interval
    else:
        sender.min_state_interval_s = timing.min_state_interval
    sender.state_interval_s = timing.default_state_interval or STATE_INTERVAL_S
