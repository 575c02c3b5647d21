"""Exceptions of the protocol core.

Protocol-level rejections (an order the vehicle refuses, a message master control drops) are
values, not exceptions: the codec returns a :class:`vda5050.codec.DecodeFailure` and the order
check returns VDA 5050 error objects. The exceptions below are for the few places where raising
is right::

    Vda5050Error
    ├── MessageError              inbound payload problems (carry topic and headerId when known)
    │   ├── DecodeError           not UTF-8, not JSON, too large, too deep
    │   ├── SchemaError           fails the message model/schema
    │   └── UnsupportedVersionError
    ├── TopicError                a topic string that does not parse, or an illegal topic level
    ├── ConfigError               bad configuration values (fail fast at startup)
    └── NotConnectedError         publishing while the MQTT session is down (raised by mqtt only)
"""

from __future__ import annotations


class Vda5050Error(Exception):
    """Base of every exception this package raises on purpose."""


class MessageError(Vda5050Error):
    """An inbound payload could not be used."""

    def __init__(
        self, message: str, *, topic: str | None = None, header_id: int | None = None
    ) -> None:
        super().__init__(message)
        self.topic = topic
        self.header_id = header_id


class DecodeError(MessageError):
    """The payload is not UTF-8 JSON within the configured limits."""


class SchemaError(MessageError):
    """The payload does not match the message model."""


class UnsupportedVersionError(MessageError):
    """The payload's protocol version is one this stack does not speak."""


class TopicError(Vda5050Error):
    """A topic string that does not parse or holds an illegal level (digest R01, R02)."""


class ConfigError(Vda5050Error):
    """A configuration value is missing or wrong."""


class NotConnectedError(Vda5050Error):
    """A publish was attempted while the MQTT session is disconnected."""
