"""What master control may send a vehicle in its operating mode (pure; R84; docs/inspect.md).

- 2.x (§6.10.6, the operating modes' table): in MANUAL, SERVICE and TEACHIN master control is
  not in control and sends no driving order or actions. A ``stateRequest`` or
  ``factsheetRequest`` asks for information and moves nothing: not judged;
- 3.0 (§6.6.6, Table 10): no orders in MANUAL, STARTUP, SERVICE and TEACH_IN, no instant
  actions either; in INTERVENED orders are allowed (the robot runs them once back in
  AUTOMATIC) and of the instant actions only ``cancelOrder``.

A mode counts from the listener's receipt of the first state that reports it, after a grace
of ``GRACE_S``: master control may have sent its message before that state reached it.
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import Final

from vda_inspect.severity import Problem, Severity

#: Seconds after the state that reported a mode before master control is held to it.
GRACE_S: Final = 0.5
NOT_IN_CONTROL_2: Final = frozenset({"MANUAL", "SERVICE", "TEACHIN"})
#: 2.x instant actions that only ask for information.
ASKING: Final = frozenset({"stateRequest", "factsheetRequest"})
NO_ORDERS_3: Final = frozenset({"MANUAL", "STARTUP", "SERVICE", "TEACH_IN"})
NO_INSTANT_ACTIONS_3: Final = NO_ORDERS_3 | {"INTERVENED"}


def order_problems(mode: str | None, held_s: float, *, v3: bool) -> list[Problem]:
    """An order sent to a vehicle that has reported ``mode`` for ``held_s`` seconds."""
    if mode is None or held_s < GRACE_S:
        return []
    if mode in (NO_ORDERS_3 if v3 else NOT_IN_CONTROL_2):
        return [("R84", f"an order sent while the vehicle is in {mode}", Severity.VIOLATION)]
    return []


def instant_action_problems(
    mode: str | None, held_s: float, action_types: Iterable[str], *, v3: bool
) -> list[Problem]:
    """Instant actions sent to a vehicle that has reported ``mode`` for ``held_s`` seconds."""
    if mode is None or held_s < GRACE_S:
        return []
    if v3:
        if mode == "INTERVENED":
            wrong = [t for t in action_types if t != "cancelOrder"]
        else:
            wrong = list(action_types) if mode in NO_INSTANT_ACTIONS_3 else []
    else:
        wrong = [t for t in action_types if t not in ASKING] if mode in NOT_IN_CONTROL_2 else []
    if not wrong:
        return []
    text = f"instant action {', '.join(sorted(set(wrong)))} sent while the vehicle is in {mode}"
    return [("R84", text, Severity.VIOLATION)]
