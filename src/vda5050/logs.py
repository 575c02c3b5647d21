"""structlog configuration; called once by each service's ``__main__``."""

from __future__ import annotations

import logging
import sys

import structlog

#: Third-party loggers that are too chatty below WARNING.
_QUIET_LIBRARIES = ("amqtt", "transitions", "mqtt", "aiomqtt", "paho", "uvicorn.access")


def configure_logging(*, json: bool | None = None, level: str = "INFO") -> None:
    """Configure structlog (and the stdlib root logger) for a service process.

    Args:
        json: render JSON lines; defaults to JSON unless stderr is a terminal.
        level: the minimum level name, e.g. ``"INFO"``.
    """
    as_json = not sys.stderr.isatty() if json is None else json
    numeric_level = logging.getLevelNamesMapping()[level.upper()]
    renderer: structlog.typing.Processor = (
        structlog.processors.JSONRenderer() if as_json else structlog.dev.ConsoleRenderer()
    )
    processors: list[structlog.typing.Processor] = [
        structlog.contextvars.merge_contextvars,
        structlog.processors.add_log_level,
        structlog.processors.TimeStamper(fmt="iso", utc=True),
    ]
    if as_json:
        processors.append(structlog.processors.dict_tracebacks)
    processors.append(renderer)
    structlog.configure(
        processors=processors,
        wrapper_class=structlog.make_filtering_bound_logger(numeric_level),
        logger_factory=structlog.PrintLoggerFactory(file=sys.stderr),
        cache_logger_on_first_use=True,
    )
    logging.basicConfig(level=numeric_level, stream=sys.stderr, format="%(name)s %(message)s")
    for name in _QUIET_LIBRARIES:
        logging.getLogger(name).setLevel(max(numeric_level, logging.WARNING))
