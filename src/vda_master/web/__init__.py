"""The live web map of the fleet: static page and assets, and its Server-Sent Events stream.

:func:`add_map` mounts it on the master's FastAPI app: ``GET /`` and ``GET /map`` serve the page,
``/map-assets/`` its CSS, JavaScript modules and icon (shipped in this package, nothing from
the internet), ``GET /events`` the live stream (:mod:`vda_master.web.stream`). See docs/web.md.
"""

from __future__ import annotations

from vda_master.web.routes import add_map

__all__ = ["add_map"]
