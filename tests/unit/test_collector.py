"""The collector tuning shared by master control and the vehicle process (vda5050.collector)."""

from __future__ import annotations

import gc

from vda5050.collector import TUNED_THRESHOLDS, tuned_collector


def test_tuning_freezes_and_restores_afterwards() -> None:
    """Inside, what existed is frozen and the tuned thresholds hold; afterwards the previous
    thresholds are back and nothing stays frozen."""
    before = gc.get_threshold()
    with tuned_collector():
        assert gc.get_threshold() == TUNED_THRESHOLDS
        assert gc.get_freeze_count() > 0
    assert gc.get_threshold() == before
    assert gc.get_freeze_count() == 0


def test_overlapping_uses_share_one_tuning() -> None:
    """A master and vehicles in one process: the tuning lasts until the last user leaves, in
    whatever order they leave, and then the previous thresholds come back."""
    before = gc.get_threshold()
    first, second = tuned_collector(), tuned_collector()
    first.__enter__()
    second.__enter__()
    first.__exit__(None, None, None)
    assert gc.get_threshold() == TUNED_THRESHOLDS
    second.__exit__(None, None, None)
    assert gc.get_threshold() == before
    assert gc.get_freeze_count() == 0
