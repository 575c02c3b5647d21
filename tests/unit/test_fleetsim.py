"""``vda-fleetsim`` (docs/fleetsim.md): a fleet sized on a graph file, simulated on a fake
clock; what it prints and writes, and what it says about input it cannot use."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from benchmarks.traffic_sim import WAREHOUSE
from vda_fleetsim.cli import main
from vda_fleetsim.simulation import first_parking_node, pace_of
from vda_fleetsim.workload import Pace
from vda_master.graph import load_graph
from vda_vehicle.config import VehicleSettings


def test_two_fleet_sizes_give_a_line_each_and_the_json_rows(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Two and four vehicles for six simulated minutes on the warehouse: a title naming the
    stations, a header, one line per size with the nodes waited at, and the same figures as
    JSON. Traffic control keeps them apart; four carry more than two."""
    out = tmp_path / "rows.json"
    argv = ["--graph", str(WAREHOUSE), "--vehicles", "2", "4", "--sim-hours", "0.1"]
    assert main([*argv, "--where", "--json", str(out)]) == 0
    printed = capsys.readouterr().out.splitlines()
    assert "149 nodes: 3 charging, 4 drop, 6 parking, 16 pick" in printed[0]
    assert "traffic control on" in printed[0]
    assert printed[1].split()[:3] == ["vehicles", "transports/h", "per"]
    assert printed[2].split()[0] == "2"
    assert printed[3].strip().startswith(("waited most at:", "nobody waited"))
    assert printed[4].split()[0] == "4"
    two, four = json.loads(out.read_text())
    assert (two["vehicles"], four["vehicles"]) == (2, 4)
    assert 0 < two["transports_per_h"] < four["transports_per_h"]
    assert "added_per_vehicle_h" not in two
    assert four["added_per_vehicle_h"] == pytest.approx(
        (four["transports_per_h"] - two["transports_per_h"]) / 2
    )
    assert four["closest_m"] >= 1.69
    assert (four["violations"], four["failed"]) == (0, 0)
    assert set(four["time_shares"]) == {"driving", "actions", "waiting", "charging", "idle"}
    assert four["time_shares"]["charging"] == 0  # batteries do not drain unless asked to


def _graph_without_drops(tmp_path: Path) -> Path:
    document = json.loads(WAREHOUSE.read_text())
    for node in document["nodes"]:
        if node.get("stationType") == "drop":
            del node["stationType"]
    path = tmp_path / "no_drops.json"
    path.write_text(json.dumps(document))
    return path


@pytest.mark.parametrize(
    ("argv", "says"),
    [
        (["--vehicles", "200"], "needs 200 distinct nodes"),
        (["--master-setting", "traffic_control"], "--master-setting 'traffic_control': give"),
        (["--vehicle-setting", "speed_max_mps=-1"], "speed_max_mps"),
        (["--graph", "nowhere.json"], "nowhere.json"),
    ],
)
def test_input_it_cannot_use_is_named_with_status_2(
    argv: list[str], says: str, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["--graph", str(WAREHOUSE), "--sim-hours", "0.01", *argv]) == 2
    assert says in capsys.readouterr().err


def test_a_graph_without_drop_stations_is_refused_saying_why(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["--graph", str(_graph_without_drops(tmp_path))]) == 2
    assert "no node with stationType 'drop'" in capsys.readouterr().err


def test_the_free_flow_pace_follows_the_vehicles_settings() -> None:
    """Top speed and turning speed from the vehicle settings, the pick's preparing and running
    time from its action catalogue (with action_durations_s)."""
    assert pace_of(VehicleSettings()) == Pace(1.5, 1.0, 4.0)
    faster = VehicleSettings.model_validate(
        {"speed_max_mps": 2.0, "angular_speed_max_radps": 2.0, "action_durations_s": {"pick": 5}}
    )
    assert pace_of(faster) == Pace(2.0, 2.0, 6.0)


def test_the_fleet_starts_at_the_first_parking_node() -> None:
    assert first_parking_node(load_graph(WAREHOUSE)) == "P1"


def test_with_draining_batteries_vehicles_go_to_charge_and_it_shows(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """--vehicle-setting battery_drain_pct_per_m: master control's energy management sends the
    vehicles to the chargers, and the time they charge is its own column."""
    out = tmp_path / "rows.json"
    drain = ["--vehicle-setting", "battery_drain_pct_per_m=0.1", "--vehicle-setting",
             "battery_start_pct=35"]  # fmt: skip
    argv = ["--graph", str(WAREHOUSE), "--vehicles", "3", "--sim-hours", "0.1", *drain]
    assert main([*argv, "--json", str(out)]) == 0
    (row,) = json.loads(out.read_text())
    assert row["time_shares"]["charging"] > 0
    assert "charging" in capsys.readouterr().out.splitlines()[1]
