"""``python -m vda_fleetsim``: the same as ``vda-fleetsim``."""

from __future__ import annotations

import sys

from vda_fleetsim.cli import main

if __name__ == "__main__":
    sys.exit(main())
