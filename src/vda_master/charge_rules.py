"""Energy management (pure): which vehicles master control sends to charge, where, and whose
charge it ends. docs/master.md, *Charging*.

VDA 5050 lists energy management among master control's functions (2.1 §4, "charging orders")
and gives it the means: a state's ``batteryState`` (``batteryCharge`` in %, ``charging``,
``reach`` in metres, §6.10.6) and the actions ``startCharging`` and ``stopCharging``
(§6.8.2, R77; ``charging`` may be false only while the vehicle is ready for orders).

- A vehicle that is available (idle, AUTOMATIC, ...) and not charging with ``batteryCharge``
  under ``charge_below_pct`` *wants a charge*; the lowest battery goes first.
- It is sent, by an order of master control's own, to the nearest free ``charging`` node,
  with the node action ``startCharging``. A charger is free when no vehicle stands on it
  (``lastNodeId``) and no active order is bound for it.
- A vehicle that charges, runs no order and has reached ``charged_pct`` is sent the instant
  action ``stopCharging``: it takes orders again.
- While every charger is taken, a vehicle that stands idle on one without charging is moved to
  a free parking node to make room; the one waiting stays available meanwhile.
- A route longer than the battery's ``reach`` is not given to the vehicle (0 and an absent
  reach count as not known: vehicles that do not estimate it send either).
"""

from __future__ import annotations

from collections.abc import Collection, Iterable, Mapping
from dataclasses import dataclass
from typing import Final

from vda5050.models import State
from vda5050.topics import AgvId

#: The note prefix of master control's own charging orders (the order view's ``note``).
CHARGING_NOTE: Final = "charging: "
#: Simulated seconds in which a vehicle whose battery did not rise since master control last
#: sent it to charge is not sent again (it may not charge at all, or report a placeholder).
RETRY_AFTER_S: Final = 600.0


@dataclass(frozen=True, slots=True)
class ChargeSettings:
    """``below_pct`` 0 turns energy management off."""

    below_pct: float = 30.0
    until_pct: float = 80.0

    @property
    def enabled(self) -> bool:
        return self.below_pct > 0


@dataclass(frozen=True, slots=True)
class ChargeAttempt:
    """When master control last sent a vehicle to charge, and its battery then."""

    at: float
    battery_pct: float


def wants_charge(state: State, settings: ChargeSettings) -> bool:
    """Under ``charge_below_pct`` and not charging."""
    battery = state.battery_state
    return settings.enabled and not battery.charging and battery.battery_charge < settings.below_pct


def charge_done(state: State, settings: ChargeSettings) -> bool:
    """Charging, at ``charged_pct`` or above."""
    battery = state.battery_state
    return settings.enabled and battery.charging and battery.battery_charge >= settings.until_pct


def retry_blocked(
    attempt: ChargeAttempt | None, battery_pct: float, now: float, retry_after_s: float
) -> bool:
    """The last attempt, less than ``retry_after_s`` ago, did not raise the battery."""
    return (
        attempt is not None
        and now - attempt.at < retry_after_s
        and battery_pct <= attempt.battery_pct
    )


def free_chargers(
    chargers: Iterable[str], standing: Collection[str], bound_for: Collection[str]
) -> list[str]:
    """The charging nodes no vehicle stands on and no active order is bound for."""
    return [c for c in chargers if c not in standing and c not in bound_for]


def spots_for(
    agv: AgvId,
    own_node: str,
    *,
    chargers: Collection[str],
    standing: Mapping[str, Collection[AgvId]],
    bound_for: Collection[str],
    free: list[str],
) -> list[str]:
    """Where ``agv`` may charge: the charger it stands on alone (no other vehicle there and no
    order bound for it), else the free ones."""
    mine = (
        own_node in chargers
        and set(standing.get(own_node, ())) == {agv}
        and own_node not in bound_for
    )
    return [own_node] if mine else free


def vacating(
    chargers: Iterable[str],
    standing: Mapping[str, Collection[AgvId]],
    bound_for: Collection[str],
    running: Collection[AgvId],
) -> list[str]:
    """Chargers whose vehicles all run an order (they drive away: free in a moment) and that
    no order is bound for; room is made only for the vehicles waiting beyond these."""
    return [
        c
        for c in chargers
        if c in standing and c not in bound_for and all(a in running for a in standing[c])
    ]


def charging_queue(
    wanting: Iterable[tuple[AgvId, float]],
) -> list[AgvId]:
    """Vehicles that want a charge, lowest battery first (ties by name)."""
    return [agv for agv, _ in sorted(wanting, key=lambda item: (item[1], str(item[0])))]


def reach_problem(state: State | None, length_m: float) -> str | None:
    """Why the battery will not carry the vehicle ``length_m`` (§6.10.6 ``reach``), or None."""
    if state is None:
        return None
    battery = state.battery_state
    if not battery.reach or length_m <= battery.reach:
        return None
    return (
        f"its battery reaches {battery.reach:g} m (batteryState.reach, at "
        f"{battery.battery_charge:g} %) and the route is {length_m:.1f} m"
    )


def charging_reason(battery_pct: float, settings: ChargeSettings) -> str:
    """The note of a charging order: why master control sent it."""
    return f"battery {round(battery_pct, 1):g} % is below charge_below_pct {settings.below_pct:g} %"
