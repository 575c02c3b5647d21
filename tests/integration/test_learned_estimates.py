"""What ``expectedFinishAt`` learned outlives a restart of master control (docs/master.md,
*Expected finish*): written to the data folder at shutdown, read at the next start."""

from __future__ import annotations

import json
from pathlib import Path
from typing import TYPE_CHECKING

import pytest

from tests.integration.master_helpers import (
    SIMULATED_BODY,
    master_with_simulated_vehicle,
    running_master,
    wait_status,
)
from vda_master.finish_times import LEARNED_FILE

if TYPE_CHECKING:
    from vda5050.broker import BrokerAddress

pytestmark = pytest.mark.integration


async def test_the_pace_learned_from_a_finished_order_is_there_after_a_restart(
    embedded_broker: BrokerAddress, unique_interface_name: str, tmp_path: Path
) -> None:
    settings: dict[str, object] = {"data_dir": str(tmp_path)}
    async with master_with_simulated_vehicle(
        embedded_broker, unique_interface_name, master_settings=settings
    ) as (master, _, client):
        created = await client.post("/orders", json={**SIMULATED_BODY, "destination": "10"})
        assert created.status_code == 201, created.text
        await wait_status(client, created.json()["orderId"], "FINISHED", timeout=20)
        learned = master.service.estimates.pace["acme"].value
        assert not (tmp_path / LEARNED_FILE).exists()  # written every 5 minutes and at the end

    written = json.loads((tmp_path / LEARNED_FILE).read_text())
    assert written["pace"]["acme"] == {"mean": learned, "n": 1}
    async with running_master(embedded_broker, unique_interface_name, **settings) as master:
        assert master.service.estimates.pace["acme"].value == learned
