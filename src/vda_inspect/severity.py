"""How bad a finding is."""

from __future__ import annotations

from enum import StrEnum


class Severity(StrEnum):
    """A violation breaks a rule; a notice is something a listener cannot tell from one
    (a message lost on the way, a restarted sender)."""

    VIOLATION = "violation"
    NOTICE = "notice"


#: (rule, text, severity) of one finding, before it is given its vehicle and topic.
Problem = tuple[str, str, Severity]
