"""Operating modes of a 3.0 mobile robot and what each implies (§6.6.6 Tables 10 and 11, §6.6.7).

The table is data so both sides read the same facts: the robot (clear the order when entering
a mode, empty ``lastNodeId``, drop zone requests) and fleet control (may it send orders or
instant actions now).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from enum import StrEnum
from types import MappingProxyType
from typing import Final, Literal

__all__ = ["MODE_RULES", "V2_NAMES", "ModeRules", "OperatingMode"]


class OperatingMode(StrEnum):
    """Who controls the robot (§6.6.6). 3.0 adds STARTUP and INTERVENED and spells TEACH_IN."""

    STARTUP = "STARTUP"
    AUTOMATIC = "AUTOMATIC"
    SEMIAUTOMATIC = "SEMIAUTOMATIC"
    INTERVENED = "INTERVENED"
    MANUAL = "MANUAL"
    SERVICE = "SERVICE"
    TEACH_IN = "TEACH_IN"

    @property
    def rules(self) -> ModeRules:
        """What this mode implies (Table 11)."""
        return MODE_RULES[self]


@dataclass(frozen=True, slots=True)
class ModeRules:
    """One row of Table 11."""

    fleet_control_in_control: bool
    #: False in STARTUP: state fields may be incomplete or invalid until start-up is over.
    state_valid: bool
    clears_order_on_entry: bool
    #: "always", "never", or "if the order cannot be continued" (MANUAL).
    empties_last_node_id: Literal["always", "never", "if_not_continuable"]
    clears_zone_requests_on_entry: bool
    #: Which instant actions fleet control may send: all, only ``cancelOrder``, or none.
    instant_actions: Literal["all", "cancel_order_only", "none"]
    orders_allowed: bool

    def allows_instant_action(self, action_type: str) -> bool:
        """Tell whether fleet control may send instant action ``action_type`` in this mode."""
        if self.instant_actions == "all":
            return True
        return self.instant_actions == "cancel_order_only" and action_type == "cancelOrder"


_AUTOMATIC = ModeRules(
    fleet_control_in_control=True,
    state_valid=True,
    clears_order_on_entry=False,
    empties_last_node_id="never",
    clears_zone_requests_on_entry=False,
    instant_actions="all",
    orders_allowed=True,
)

#: Table 11, one row per mode.
MODE_RULES: Final[Mapping[OperatingMode, ModeRules]] = MappingProxyType(
    {
        OperatingMode.AUTOMATIC: _AUTOMATIC,
        OperatingMode.SEMIAUTOMATIC: _AUTOMATIC,
        # INTERVENED keeps the order (it resumes on return to (SEMI)AUTOMATIC); orders may be
        # sent for later, instant actions only cancelOrder.
        OperatingMode.INTERVENED: ModeRules(
            fleet_control_in_control=False,
            state_valid=True,
            clears_order_on_entry=False,
            empties_last_node_id="never",
            clears_zone_requests_on_entry=True,
            instant_actions="cancel_order_only",
            orders_allowed=True,
        ),
        OperatingMode.MANUAL: ModeRules(
            fleet_control_in_control=False,
            state_valid=True,
            clears_order_on_entry=True,
            empties_last_node_id="if_not_continuable",
            clears_zone_requests_on_entry=True,
            instant_actions="none",
            orders_allowed=False,
        ),
        OperatingMode.STARTUP: ModeRules(
            fleet_control_in_control=False,
            state_valid=False,
            clears_order_on_entry=True,
            empties_last_node_id="always",
            clears_zone_requests_on_entry=True,
            instant_actions="none",
            orders_allowed=False,
        ),
        OperatingMode.SERVICE: ModeRules(
            fleet_control_in_control=False,
            state_valid=True,
            clears_order_on_entry=True,
            empties_last_node_id="always",
            clears_zone_requests_on_entry=True,
            instant_actions="none",
            orders_allowed=False,
        ),
        OperatingMode.TEACH_IN: ModeRules(
            fleet_control_in_control=False,
            state_valid=True,
            clears_order_on_entry=True,
            empties_last_node_id="always",
            clears_zone_requests_on_entry=True,
            instant_actions="none",
            orders_allowed=False,
        ),
    }
)

#: Each mode's name in 2.x terms (§6.10.6 Table 1), for a side that knows only the 2.x modes:
#: master control's core reading a 3.0 state, and a 2.x vehicle whose robot reports a 3.0 mode.
#: STARTUP (fleet control not in control, no orders) reads as SERVICE, INTERVENED (an operator
#: steers; no orders started) as MANUAL; TEACH_IN is spelled TEACHIN.
V2_NAMES: Final[Mapping[OperatingMode, str]] = MappingProxyType(
    {
        OperatingMode.STARTUP: "SERVICE",
        OperatingMode.AUTOMATIC: "AUTOMATIC",
        OperatingMode.SEMIAUTOMATIC: "SEMIAUTOMATIC",
        OperatingMode.INTERVENED: "MANUAL",
        OperatingMode.MANUAL: "MANUAL",
        OperatingMode.SERVICE: "SERVICE",
        OperatingMode.TEACH_IN: "TEACHIN",
    }
)
