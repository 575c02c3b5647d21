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
