"""A webhook receiver for the tests: records every POST on a free port, and answers with the
statuses it is given (then 200)."""

from __future__ import annotations

import json
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from typing import Any


@dataclass
class Received:
    """What came: each request's headers and body, in arrival order."""

    url: str = ""
    requests: list[tuple[dict[str, str], bytes]] = field(default_factory=list)
    #: Statuses to answer the next requests with, first to last; then 200.
    answers: list[int] = field(default_factory=list)
    lock: threading.Lock = field(default_factory=threading.Lock)

    def events(self) -> list[dict[str, Any]]:
        """The bodies of the requests answered 2xx, parsed."""
        with self.lock:
            return [
                json.loads(body) for headers, body in self.requests if headers["x-answer"] == "200"
            ]


@contextmanager
def receiving(answers: list[int] | None = None) -> Iterator[Received]:
    """A receiver at ``Received.url``; ``answers``: statuses for the first requests."""
    received = Received(answers=list(answers or []))

    class Handler(BaseHTTPRequestHandler):
        def do_POST(self) -> None:
            body = self.rfile.read(int(self.headers.get("Content-Length", "0")))
            with received.lock:
                status = received.answers.pop(0) if received.answers else 200
                headers = {k.lower(): v for k, v in self.headers.items()}
                headers["x-answer"] = str(status)
                received.requests.append((headers, body))
            self.send_response(status)
            self.send_header("Content-Length", "0")
            self.end_headers()

        def log_message(self, *_args: object) -> None:
            return

    server = ThreadingHTTPServer(("127.0.0.1", 0), Handler)
    threading.Thread(target=server.serve_forever, daemon=True).start()
    received.url = f"http://127.0.0.1:{server.server_address[1]}/hooks/vda"
    try:
        yield received
    finally:
        server.shutdown()
        server.server_close()
