"""Which vehicles master control tracks (issue 14: a bounded fleet view).

With ``accept_unlisted_vehicles`` (the default) every vehicle that publishes a valid message is
tracked. Without it only the ``robots`` of the configuration are; messages of others are ignored
with one log line per vehicle, for at most :data:`LOGGED_LIMIT` vehicles, then one summary line
per :data:`SUMMARY_EVERY` ignored messages, so made-up serial numbers cannot grow memory or logs.
"""

from __future__ import annotations

from typing import Final

import structlog

from vda5050.topics import AgvId

log = structlog.get_logger()

LOGGED_LIMIT: Final = 100
SUMMARY_EVERY: Final = 1000


class Admission:
    """Decides per message whether its vehicle belongs to the tracked fleet."""

    def __init__(self, listed: frozenset[AgvId], *, accept_unlisted: bool) -> None:
        self.listed = listed
        self.accept_unlisted = accept_unlisted
        self._logged: set[AgvId] = set()
        self.ignored_messages = 0

    def admits(self, agv: AgvId) -> bool:
        """Whether messages of ``agv`` are folded into the fleet view."""
        if self.accept_unlisted or agv in self.listed:
            return True
        self.ignored_messages += 1
        if agv not in self._logged and len(self._logged) < LOGGED_LIMIT:
            self._logged.add(agv)
            log.warning(
                "vehicle.ignored",
                agv=str(agv),
                reason="not in the robots list and accept_unlisted_vehicles is false",
            )
        elif self.ignored_messages % SUMMARY_EVERY == 0:
            log.warning("vehicle.ignored_summary", messages=self.ignored_messages)
        return False
