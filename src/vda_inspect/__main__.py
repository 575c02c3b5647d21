"""``python -m vda_inspect``: the same as the ``vda-inspect`` console script."""

from vda_inspect.cli import main

raise SystemExit(main())
