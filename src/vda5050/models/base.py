"""Shared building blocks of the VDA 5050 wire models.

Every wire model is a frozen pydantic v2 model whose Python attributes are snake_case and whose
JSON names are the camelCase names of the standard. Unknown (vendor) fields are accepted and
ignored on input (the official schemas allow additional properties); unset optional fields are
left out on output (the codec dumps with ``exclude_none``). NaN and Infinity are rejected
everywhere (VDA 5050 2.1 §6.1.4).
"""

from __future__ import annotations

import math
from typing import Annotated, Any, ClassVar

from pydantic import BaseModel, ConfigDict, Field
from pydantic.alias_generators import to_camel

UINT32_MAX = 4_294_967_295

#: Marks a field that exists only from VDA 5050 2.1.0 on; the 2.0.0 schemas leave it out.
SINCE_2_1: dict[str, Any] = {"x-vda5050-since": "2.1.0"}

# The official schemas bound angles by ±3.14159265359, a hair wider than math.pi; accept that on
# input so a rounded π from another implementation is not rejected.
_PI_BOUND = 3.14159265359

UInt32 = Annotated[int, Field(ge=0, le=UINT32_MAX)]
Angle = Annotated[float, Field(ge=-_PI_BOUND, le=_PI_BOUND)]
NonNegativeFloat = Annotated[float, Field(ge=0)]
Percent = Annotated[float, Field(ge=0, le=100)]
#: ISO 8601 / RFC 3339 date-time. Senders use milliseconds and ``Z`` (§6.4); receivers accept any
#: RFC 3339 form.
Timestamp = Annotated[
    str,
    Field(
        pattern=r"^\d{4}-\d{2}-\d{2}[Tt]\d{2}:\d{2}:\d{2}(\.\d+)?([Zz]|[+-]\d{2}:\d{2})$",
        json_schema_extra={"format": "date-time"},
    ),
]
#: ``Major.Minor.Patch`` (digest §11 item 12).
VersionString = Annotated[str, Field(pattern=r"^\d+\.\d+\.\d+$")]


#: Frozen models with snake_case attributes, camelCase JSON names and no NaN/Infinity.
CAMEL_CASE_CONFIG = ConfigDict(
    alias_generator=to_camel,
    validate_by_name=True,
    validate_by_alias=True,
    serialize_by_alias=True,
    frozen=True,
    allow_inf_nan=False,
)


class WireModel(BaseModel):
    """Base of every VDA 5050 wire object; vendor fields are accepted and ignored."""

    model_config = ConfigDict(**CAMEL_CASE_CONFIG, extra="ignore")

    #: The VDA 5050 major version whose wire format the model describes; the codec checks a
    #: message's ``version`` against it (R17). 3.0 models override it (``vda5050.models.v3``).
    vda_major: ClassVar[int] = 2


class Message(WireModel):
    """A message whose five header fields are all required (§6.4)."""

    header_id: UInt32
    timestamp: Timestamp
    version: VersionString
    manufacturer: str
    serial_number: str

    def header_fields(self) -> dict[str, Any]:
        """The five header fields, to carry them into a message of the other generation."""
        return {
            "header_id": self.header_id,
            "timestamp": self.timestamp,
            "version": self.version,
            "manufacturer": self.manufacturer,
            "serial_number": self.serial_number,
        }


class LenientHeaderMessage(WireModel):
    """A message whose schema does not require the header (2.x visualization, 2.1 factsheet).

    The services always send the full header (the stamper fills it); receivers accept a partial one.
    """

    header_id: UInt32 | None = None
    timestamp: Timestamp | None = None
    version: VersionString | None = None
    manufacturer: str | None = None
    serial_number: str | None = None


def is_finite_json(value: object) -> bool:
    """Tell whether a JSON value holds no NaN or infinite number at any depth (§6.1.4)."""
    if isinstance(value, float):
        return math.isfinite(value)
    if isinstance(value, list):
        return all(is_finite_json(item) for item in value)
    if isinstance(value, dict):
        return all(is_finite_json(item) for item in value.values())
    return True
