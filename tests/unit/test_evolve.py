"""vda5050.evolve: the pure cores' fast copy equals dataclasses.replace."""

from __future__ import annotations

from dataclasses import FrozenInstanceError, dataclass, field, replace

import pytest
from hypothesis import given
from hypothesis import strategies as st

from vda5050 import codec
from vda5050.clock import FakeClock
from vda5050.evolve import evolve
from vda5050.testing import make_order
from vda5050.topics import Topic
from vda_vehicle.model import VehicleState
from vda_vehicle.testing import make_runtime


@dataclass(frozen=True, slots=True)
class Plain:
    a: int
    b: tuple[int, ...] = ()
    c: str = "c"


@dataclass(frozen=True, slots=True)
class Checked:
    low: int
    high: int

    def __post_init__(self) -> None:
        if self.low > self.high:
            msg = "low above high"
            raise ValueError(msg)


@dataclass(frozen=True)
class NoSlots:
    a: int
    b: list[int] = field(default_factory=list)


@dataclass(frozen=True, slots=True)
class Derived:
    a: int
    doubled: int = field(init=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "doubled", 2 * self.a)


def _driving_state() -> VehicleState:
    runtime, _ = make_runtime(FakeClock())
    runtime.attach(lambda *_: None)
    order = make_order(["n0", "n1", "n2"], positions=[(0, 0), (8, 0), (16, 0)])
    runtime.handle_order(runtime.topics[Topic.ORDER], codec.encode(order))
    runtime.tick(0.5, 0.5)
    return runtime.state


@given(a=st.integers(), b=st.lists(st.integers()).map(tuple), change=st.sampled_from("abc"))
def test_a_plain_frozen_slotted_copy_equals_replace(
    a: int, b: tuple[int, ...], change: str
) -> None:
    original = Plain(a, b)
    value = {"a": a + 1, "b": (*b, 1), "c": "other"}[change]
    copied = evolve(original, **{change: value})
    assert copied == replace(original, **{change: value})  # type: ignore[arg-type]
    assert copied is not original
    assert original == Plain(a, b)  # the original is untouched


def test_the_vehicle_state_copy_equals_replace_and_stays_frozen() -> None:
    state = _driving_state()
    changes = {"battery_charge": 42.0, "distance_since_last_node": 1.5, "revision": 9}
    copied = evolve(state, **changes)
    assert copied == replace(state, **changes)  # type: ignore[arg-type]
    assert copied.nodes is state.nodes  # unchanged fields are shared, as replace shares them
    with pytest.raises(FrozenInstanceError):
        copied.battery_charge = 1.0  # type: ignore[misc]


def test_an_unknown_field_is_a_type_error_naming_it() -> None:
    with pytest.raises(TypeError, match="Plain has no field"):
        evolve(Plain(1), d=4)
    with pytest.raises(TypeError):
        evolve(_driving_state(), speed=3)


def test_classes_with_init_logic_go_through_replace() -> None:
    with pytest.raises(ValueError, match="low above high"):
        evolve(Checked(1, 2), low=5)  # __post_init__ still validates
    assert evolve(Derived(2), a=5).doubled == 10  # a derived field is derived again
    assert evolve(NoSlots(1, [2]), a=3) == NoSlots(3, [2])
