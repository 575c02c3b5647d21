"""Exceptions of the store.

::

    Vda5050Error
    ├── ConfigError                  a database URL that cannot be used (vda5050.errors)
    └── StoreError                   the store could not do what was asked
        ├── StoreUnavailableError    the database cannot be reached or is busy: try again later
        └── StoreWriteRejectedError  the database refused the data: retrying will not help
"""

from __future__ import annotations

from vda5050.errors import Vda5050Error


class StoreError(Vda5050Error):
    """The store could not do what was asked."""


class StoreUnavailableError(StoreError):
    """The database cannot be reached, went away, or is busy; the same request may succeed
    later."""


class StoreWriteRejectedError(StoreError):
    """The database refused the data itself (a constraint, a value it cannot hold); writing the
    same records again fails again."""
