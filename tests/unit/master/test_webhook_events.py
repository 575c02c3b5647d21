"""What a webhook event says and how a delivery is judged (docs/master.md, *Webhooks*)."""

from __future__ import annotations

import hashlib
import hmac

import pytest
from pydantic import ValidationError

from vda5050.topics import AgvId
from vda_master.config import MasterConfig
from vda_master.webhook_events import (
    Verdict,
    connection_event,
    order_event,
    retry_delay,
    signature,
    stamped,
    verdict,
)


def test_an_order_event_names_the_order_both_statuses_the_vehicle_and_why() -> None:
    event = order_event("o1", "FAILED", "RUNNING", AgvId("acme", "r1"), "pick failed: no load")
    assert stamped(event, 7, "2026-12-03T08:00:00.000Z") == {
        "eventId": 7,
        "timestamp": "2026-12-03T08:00:00.000Z",
        "type": "order.status",
        "orderId": "o1",
        "status": "FAILED",
        "previousStatus": "RUNNING",
        "manufacturer": "acme",
        "serialNumber": "r1",
        "reason": "pick failed: no load",
        "expectedFinishAt": None,
    }
    queued = order_event("o2", "QUEUED", None, None, "")
    assert (queued["manufacturer"], queued["serialNumber"], queued["reason"]) == (None, None, None)
    running = order_event(
        "o3", "RUNNING", "ACCEPTED", None, None, expected_finish="2026-12-03T08:01:30.000Z"
    )
    assert running["expectedFinishAt"] == "2026-12-03T08:01:30.000Z"


def test_a_connection_event_names_the_vehicle_and_both_states() -> None:
    assert connection_event(AgvId("acme", "r1"), "CONNECTIONBROKEN", "ONLINE") == {
        "type": "vehicle.connection",
        "manufacturer": "acme",
        "serialNumber": "r1",
        "connectionState": "CONNECTIONBROKEN",
        "previousConnectionState": "ONLINE",
    }


def test_the_signature_is_the_hmac_sha256_of_the_body_a_receiver_can_check() -> None:
    body = b'{"eventId":1}'
    expected = hmac.new(b"secret", body, hashlib.sha256).hexdigest()
    assert signature("secret", body) == f"sha256={expected}"
    assert signature("other", body) != signature("secret", body)


@pytest.mark.parametrize(
    ("status", "expected"),
    [
        (200, Verdict.DELIVERED),
        (204, Verdict.DELIVERED),
        (None, Verdict.RETRY),
        (500, Verdict.RETRY),
        (503, Verdict.RETRY),
        (408, Verdict.RETRY),
        (429, Verdict.RETRY),
        (400, Verdict.REFUSED),
        (404, Verdict.REFUSED),
        (301, Verdict.REFUSED),
    ],
)
def test_what_an_answer_means_for_the_delivery(status: int | None, expected: Verdict) -> None:
    assert verdict(status) is expected


def test_retries_wait_twice_as_long_each_time_up_to_30_s() -> None:
    assert [retry_delay(n) for n in range(1, 9)] == [0.5, 1, 2, 4, 8, 16, 30, 30]


def test_webhook_urls_come_as_a_list_or_a_comma_separated_string_and_must_be_http() -> None:
    config = MasterConfig.model_validate({"webhook_urls": "http://wms:8080/a, https://mes/b"})
    assert config.webhook_urls == ["http://wms:8080/a", "https://mes/b"]
    with pytest.raises(ValidationError, match="webhook URL 'wms:8080/a' is not an absolute"):
        MasterConfig.model_validate({"webhook_urls": ["wms:8080/a"]})
