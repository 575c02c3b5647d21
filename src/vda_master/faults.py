"""Crash points for tests of recovery (issue 10): ``VDA_FAULT_CRASH_AT=<point>`` in the
environment makes master control exit at once (``os._exit``: no clean-up, no flush, like a
power cut) the first time it reaches that point. Unset, a crash point costs one dict lookup.

Points: ``after_write_ahead`` (a new order is committed to the store, its first message not yet
published).
"""

from __future__ import annotations

import os
import sys
from typing import Final

#: Exit status of a provoked crash (what a SIGKILL'd process reports, minus the signal).
CRASH_EXIT_CODE: Final = 137
ENV_VAR: Final = "VDA_FAULT_CRASH_AT"


def crash_point(name: str) -> None:
    """Exit now if the environment asks to crash at ``name``."""
    if os.environ.get(ENV_VAR) == name:
        sys.stderr.write(f"vda-master: crashing at {name!r} ({ENV_VAR})\n")
        sys.stderr.flush()
        os._exit(CRASH_EXIT_CODE)
