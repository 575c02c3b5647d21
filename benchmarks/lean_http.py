"""A minimal HTTP/1.1 keep-alive client for the benchmarks' request bursts.

The benchmarks run on the same two cores as the stack they measure. httpx costs ~2 ms of CPU per
request (`benchmarks/fleet.py` measured 2.2 CPU-s for 1000 `POST /orders`), CPU taken from the
master and the vehicles while they work. This client writes a request with one `write` and reads
the answer by its Content-Length, on one connection per concurrent caller: a few tens of µs.
It speaks only what `vda-master` (uvicorn) answers with: a status line, headers with
Content-Length, a body. Anything else (chunked bodies, a closed connection) raises.
"""

from __future__ import annotations

import asyncio
from types import TracebackType
from typing import Self

import orjson

__all__ = ["LeanConnection"]


class LeanConnection:
    """One keep-alive connection; requests on it go one after the other."""

    def __init__(self, host: str, port: int) -> None:
        self._host, self._port = host, port
        self._reader: asyncio.StreamReader | None = None
        self._writer: asyncio.StreamWriter | None = None

    async def __aenter__(self) -> Self:
        self._reader, self._writer = await asyncio.open_connection(self._host, self._port)
        return self

    async def __aexit__(
        self,
        kind: type[BaseException] | None,
        error: BaseException | None,
        trace: TracebackType | None,
    ) -> None:
        if self._writer is not None:
            self._writer.close()
            await self._writer.wait_closed()

    async def post_json(self, path: str, body: object) -> tuple[int, bytes]:
        """POST ``body`` as JSON; the status code and the answer's body."""
        payload = orjson.dumps(body)
        head = (
            f"POST {path} HTTP/1.1\r\nHost: {self._host}:{self._port}\r\n"
            f"Content-Type: application/json\r\nContent-Length: {len(payload)}\r\n\r\n"
        )
        return await self._exchange(head.encode() + payload)

    async def get(self, path: str) -> tuple[int, bytes]:
        """GET ``path``; the status code and the answer's body."""
        head = f"GET {path} HTTP/1.1\r\nHost: {self._host}:{self._port}\r\n\r\n"
        return await self._exchange(head.encode())

    async def _exchange(self, request: bytes) -> tuple[int, bytes]:
        if self._reader is None or self._writer is None:
            msg = "LeanConnection used outside 'async with'"
            raise RuntimeError(msg)
        self._writer.write(request)
        head = await self._reader.readuntil(b"\r\n\r\n")
        lines = head.decode("latin-1").split("\r\n")
        status = int(lines[0].split(" ", 2)[1])
        length = None
        for line in lines[1:]:
            name, _, value = line.partition(":")
            if name.lower() == "content-length":
                length = int(value)
            elif name.lower() == "transfer-encoding":
                msg = f"the server answered with Transfer-Encoding {value.strip()}"
                raise RuntimeError(msg)
        if length is None:
            msg = f"the server's answer to {request[:40]!r} has no Content-Length"
            raise RuntimeError(msg)
        return status, await self._reader.readexactly(length)
