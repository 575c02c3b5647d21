"""The simulated battery (docs/vehicle.md): it drains with distance, and a vehicle run dry
stops with the FATAL error batteryLowError until it is charged, as vda-5050-lib's virtual AGV
does (§6.10.5, R103: the error is listed while it holds and gone once cleared; FATAL needs an
operator; §6.8.2 startCharging, R77)."""

from __future__ import annotations

from vda5050.models import ActionStatus, ErrorLevel
from vda5050.testing import make_order
from vda_vehicle.instant import receive_instant_actions
from vda_vehicle.order_executor import apply_order
from vda_vehicle.testing import action, instant, make_caps, make_vehicle, run, run_until

#: 0.5 % per metre: 2 % of charge is 4 m.
CAPS = make_caps(battery_drain_pct_per_m=0.5)
LINE = make_order(["a", "b", "c"], positions=[(0.0, 0.0), (10.0, 0.0), (20.0, 0.0)])


def _battery_low(state: object) -> list[object]:
    return [e for e in state.errors if e.error_type == "batteryLowError"]  # type: ignore[attr-defined]


def test_a_vehicle_run_dry_stops_until_it_is_charged_then_drives_on() -> None:
    state = apply_order(make_vehicle(battery_charge=3.0), LINE, "new", CAPS)
    state = run(state, CAPS, 10)
    # 3 % - the 1 % limit = 4 m, and the tick that crossed it
    assert 4.0 <= state.pose.x < 4.5
    assert not state.driving
    (error,) = _battery_low(state)
    assert error.error_level is ErrorLevel.FATAL  # type: ignore[attr-defined]
    stopped = state.pose
    assert run(state, CAPS, 5).pose == stopped  # it stays, order and all

    state = receive_instant_actions(state, instant(action("startCharging", "c1")), CAPS)
    state = run_until(state, CAPS, lambda s: not _battery_low(s), limit_s=40)
    assert state.battery_charge >= 11.0  # the limit + 10 %
    state = run_until(state, CAPS, lambda s: not s.nodes, limit_s=60)
    assert state.last_node_id == "c"
    assert not state.charging  # driving off ended the charge
    assert {r.action_id: r.status for r in state.actions}["c1"] is ActionStatus.FINISHED


def test_no_stop_with_the_limit_at_zero_or_while_the_battery_lasts() -> None:
    for caps, charge in ((make_caps(battery_drain_pct_per_m=0.5, battery_stop_pct=0.0), 3.0),
                         (CAPS, 20.0)):  # fmt: skip
        state = apply_order(make_vehicle(battery_charge=charge), LINE, "new", caps)
        state = run_until(state, caps, lambda s: not s.nodes, limit_s=60)
        assert state.last_node_id == "c"
        assert _battery_low(state) == []
