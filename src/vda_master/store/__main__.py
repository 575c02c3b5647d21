"""``python -m vda_master.store revision "message"``: render a new, empty schema migration."""

from __future__ import annotations

import sys

from vda_master.store.migrate import main

if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
