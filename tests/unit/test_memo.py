"""IdentityMemo: a derived value per (object, extra), never another object's."""

from __future__ import annotations

from vda5050.memo import IdentityMemo


def test_one_build_per_owner_and_extra_and_none_for_an_equal_other_object() -> None:
    """The same object and extra get the remembered value; an equal but different object, or
    another extra, is built anew; past the limit everything is built again."""
    memo: IdentityMemo[str] = IdentityMemo(limit=3)
    builds: list[str] = []

    def build(tag: str) -> str:
        builds.append(tag)
        return tag

    owner, twin = [1, 2], [1, 2]
    assert memo.get(owner, "a", lambda: build("first")) == "first"
    assert memo.get(owner, "a", lambda: build("again")) == "first"
    assert memo.get(twin, "a", lambda: build("twin")) == "twin"
    assert memo.get(owner, "b", lambda: build("other extra")) == "other extra"
    assert builds == ["first", "twin", "other extra"]
    memo.get([3], None, lambda: build("fourth"))  # over the limit: all forgotten
    assert memo.get(owner, "a", lambda: build("rebuilt")) == "rebuilt"


def test_a_pair_of_owners_is_remembered_by_both_identities() -> None:
    """Two objects together key one value; swapping either for an equal twin builds anew."""
    memo: IdentityMemo[str] = IdentityMemo(limit=10)
    first, second, twin = [1], [2], [2]
    assert memo.get_pair(first, second, lambda: "built") == "built"
    assert memo.get_pair(first, second, lambda: "again") == "built"
    assert memo.get_pair(first, twin, lambda: "twin") == "twin"
    assert memo.get_pair(second, first, lambda: "swapped") == "swapped"
