"""Building blocks of the VDA 5050 3.0.0 wire models.

The conventions are those of the 2.x models (:mod:`vda5050.models.base`): frozen pydantic v2
models, snake_case attributes, camelCase JSON names, vendor fields accepted and ignored (no 3.0
schema forbids additional properties), unset optional fields left out on output, no NaN or
Infinity (3.0 §7.1.4). Section numbers (§) in this package are those of the 3.0.0 text.
"""

from __future__ import annotations

from typing import ClassVar

from vda5050.models.base import Message, WireModel

#: The 3.0 versions this package describes.
VERSION = "3.0.0"


class V3WireModel(WireModel):
    """Base of every 3.0 wire object."""

    vda_major: ClassVar[int] = 3


class V3Message(Message, V3WireModel):
    """A 3.0 message: the five header fields are required on every topic (§7.2), including
    visualization and factsheet, whose 2.x schemas left the header optional."""

    vda_major: ClassVar[int] = 3
