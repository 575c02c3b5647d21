"""Which vehicle may pick and which may drop, by the loads its state reports (pure).

A vehicle lists what it carries in its state's ``loads`` (§6.10.6): an empty list means it
carries nothing, a missing one that it cannot tell. Master control reads it before it sends
an order whose destination actions handle a load (the predefined ``pick`` and ``drop``,
§6.8.2; the first of them in the order's list decides):

- a ``pick`` needs a free load position: none is free when every position the factsheet lists
  (``loadSpecification.loadPositions``) holds a load, or when the ``lhd`` asked for holds one;
- a ``drop`` needs a load to drop: one at the ``lhd`` asked for, with the ``loadId`` and
  ``loadType`` asked for;
- either, when it names a ``loadType``, needs a load set for it (``loadSpecification.loadSets``,
  at the ``lhd`` asked for when the set lists its positions): a vehicle without one is
  :attr:`Fit.UNSUITED`, never only busy, so a named one is refused for good (422) and a queued
  order waits for a vehicle that has one. A factsheet that lists no load sets says nothing.

Tolerant where the vehicle says too little: without ``loads`` in its state, without load
positions in its factsheet (a loaded vehicle may have room for another) or with loads that
carry no ``loadId``/``loadPosition`` to compare, the fit is :attr:`Fit.UNKNOWN`: master control
sends a named vehicle the order and chooses such a vehicle only when none known to fit can go.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from enum import Enum

from pydantic import JsonValue

from vda5050.models import Factsheet, Load
from vda5050.models.factsheet import LoadSet
from vda_master.capabilities import ActionSpec

PICK = "pick"
DROP = "drop"


class Fit(Enum):
    """How a vehicle's loads suit an order's load action."""

    FITS = "fits"
    #: The vehicle does not say enough to tell; it may well fit.
    UNKNOWN = "unknown"
    #: Not now: what it carries (or does not) stands in the way.
    REFUSED = "refused"
    #: Never: its factsheet's load sets do not take the load type asked for.
    UNSUITED = "unsuited"


@dataclass(frozen=True, slots=True)
class LoadNeed:
    """What the order's first load action asks of the vehicle: ``action`` is ``pick``,
    ``drop`` or None (no load action); ``lhd``, ``load_id`` and ``load_type`` as its parameters
    name them."""

    action: str | None = None
    lhd: str | None = None
    load_id: str | None = None
    load_type: str | None = None


@dataclass(frozen=True, slots=True)
class LoadFit:
    fit: Fit
    #: Why not (REFUSED) or why it cannot be told (UNKNOWN): a lowercase clause.
    reason: str = ""


NO_NEED = LoadNeed()
_FITS = LoadFit(Fit.FITS)


def load_need(actions: Sequence[ActionSpec]) -> LoadNeed:
    """The need of the first ``pick`` or ``drop`` among ``actions``."""
    for spec in actions:
        if spec.action_type in (PICK, DROP):
            params = spec.parameters
            return LoadNeed(
                spec.action_type,
                _text(params, "lhd"),
                _text(params, "loadId"),
                _text(params, "loadType"),
            )
    return NO_NEED


def load_fit(loads: Sequence[Load] | None, factsheet: Factsheet | None, need: LoadNeed) -> LoadFit:
    """How a vehicle reporting ``loads`` (None: not reported) suits ``need``."""
    if need.action is None:
        return _FITS
    unsuited = load_set_problem(factsheet, need)
    if unsuited is not None:
        return LoadFit(Fit.UNSUITED, unsuited)
    if loads is None:
        return LoadFit(Fit.UNKNOWN, "its state does not report its loads")
    if need.action == PICK:
        return _pick_fit(loads, load_positions(factsheet), need)
    return _drop_fit(loads, need)


def load_positions(factsheet: Factsheet | None) -> tuple[str, ...] | None:
    """The load positions the factsheet lists (None: it lists none)."""
    spec = factsheet.load_specification if factsheet is not None else None
    positions = spec.load_positions if spec is not None else None
    return tuple(positions) if positions else None


def load_sets(factsheet: Factsheet | None) -> tuple[LoadSet, ...]:
    """The load sets the factsheet lists (``loadSpecification.loadSets``; none without one)."""
    spec = factsheet.load_specification if factsheet is not None else None
    return tuple(spec.load_sets or ()) if spec is not None else ()


def load_set_problem(factsheet: Factsheet | None, need: LoadNeed) -> str | None:
    """Why no load set of ``factsheet`` takes ``need``'s load type (at its ``lhd``, when the
    set lists positions), or None: it has one, or the need names no type, or the factsheet
    lists no load sets."""
    if need.action is None or need.load_type is None:
        return None  # most orders: nothing to look up
    sets = load_sets(factsheet)
    if not sets:
        return None
    of_type = [s for s in sets if s.load_type == need.load_type]
    if not of_type:
        taken = ", ".join(sorted({repr(s.load_type) for s in sets}))
        return f"its factsheet's load sets take {taken}, not load type {need.load_type!r}"
    if need.lhd is None or any(
        not s.load_positions or need.lhd in s.load_positions for s in of_type
    ):
        return None
    at = sorted({p for s in of_type for p in s.load_positions or ()})
    return (
        f"its factsheet's load sets take load type {need.load_type!r} on "
        f"{', '.join(repr(p) for p in at)} only, not on load handling device {need.lhd!r}"
    )


def _pick_fit(loads: Sequence[Load], positions: tuple[str, ...] | None, need: LoadNeed) -> LoadFit:
    if need.lhd is not None:
        held = [load for load in loads if load.load_position == need.lhd]
        if held:
            return LoadFit(
                Fit.REFUSED,
                f"its load handling device {need.lhd!r} holds {_names(held)}: a pick needs it free",
            )
    if not loads:
        return _FITS
    if positions is None:
        return LoadFit(
            Fit.UNKNOWN, f"it carries {_names(loads)} and its factsheet lists no load positions"
        )
    if len(loads) >= len(positions):
        return LoadFit(
            Fit.REFUSED,
            f"it carries {_names(loads)} on its {_count(len(positions), 'load position')}: "
            "a pick needs a free one",
        )
    return _FITS


def _drop_fit(loads: Sequence[Load], need: LoadNeed) -> LoadFit:
    asked = _describe_asked(need)
    if not loads:
        return LoadFit(Fit.REFUSED, f"it carries no load{asked} to drop")
    exact = loose = False
    for load in loads:
        matches = [
            (wanted, have)
            for wanted, have in (
                (need.lhd, load.load_position),
                (need.load_id, load.load_id),
                (need.load_type, load.load_type),
            )
            if wanted is not None
        ]
        if all(have == wanted for wanted, have in matches):
            exact = True
        elif all(have in (wanted, None) for wanted, have in matches):
            loose = True
    if exact:
        return _FITS
    if loose:
        return LoadFit(Fit.UNKNOWN, f"its loads do not say whether one is the load{asked}")
    return LoadFit(Fit.REFUSED, f"it carries no load{asked} to drop (it carries {_names(loads)})")


def _describe_asked(need: LoadNeed) -> str:
    parts = []
    if need.load_id is not None:
        parts.append(f" {need.load_id!r}")
    if need.load_type is not None:
        parts.append(f" of type {need.load_type!r}")
    if need.lhd is not None:
        parts.append(f" on load handling device {need.lhd!r}")
    return "".join(parts)


def _names(loads: Sequence[Load]) -> str:
    """``load 'A'``, ``loads 'A', 'B'``; a load without an id counts as ``a load``."""
    named = [repr(load.load_id) for load in loads if load.load_id]
    unnamed = len(loads) - len(named)
    if unnamed == len(loads):
        return "a load" if unnamed == 1 else f"{unnamed} loads"
    words = ", ".join(named) + (f" and {_count(unnamed, 'more')}" if unnamed else "")
    return f"load {words}" if len(loads) == 1 else f"loads {words}"


def _count(number: int, noun: str) -> str:
    return f"{number} {noun}" if number == 1 or noun == "more" else f"{number} {noun}s"


def _text(params: Mapping[str, JsonValue], key: str) -> str | None:
    value = params.get(key)
    return value if isinstance(value, str) and value else None
