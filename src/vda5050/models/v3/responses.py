"""Topic ``responses`` (3.0): fleet control → mobile robot (§4.3, §6.9, §7.5).

Fleet control answers the requests a robot states in its state message (``zoneRequests``,
``edgeRequests``), each response naming one request by its ``requestId``.
"""

from __future__ import annotations

from enum import StrEnum

from vda5050.models.base import Timestamp
from vda5050.models.v3.base import V3Message, V3WireModel

__all__ = ["GrantType", "Response", "Responses"]


class GrantType(StrEnum):
    """Fleet control's decision on a request (§6.9)."""

    GRANTED = "GRANTED"
    QUEUED = "QUEUED"
    REVOKED = "REVOKED"
    REJECTED = "REJECTED"


class Response(V3WireModel):
    """The answer to one request.

    The message table (§7.5) and the official schema name the decision ``grantType``; the prose
    of §6.4.3 calls it ``responseType``. The field-level table and the schema agree, so
    ``grantType`` is used.
    """

    request_id: str
    grant_type: GrantType
    #: Until when a GRANTED request holds; sent only with GRANTED (§7.5). Resending a response
    #: with a later leaseExpiry extends the lease (§6.9).
    lease_expiry: Timestamp | None = None


class Responses(V3Message):
    """A batch of responses to the robot's requests (§7.5)."""

    responses: list[Response]
