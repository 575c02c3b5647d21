"""The persistent map behind the traffic state: updates never change the original."""

from __future__ import annotations

from hypothesis import given
from hypothesis import strategies as st

from vda_master.traffic.pmap import PMap


def test_updates_leave_the_original_unchanged() -> None:
    """Setting and removing keys returns new maps; the old one still answers as before."""
    empty: PMap[str, int] = PMap()
    one = empty.set("a", 1)
    two = one.update(put=[("b", 2), ("a", 3)])
    assert (empty.get("a"), one.get("a"), two.get("a"), two.get("b")) == (None, 1, 3, 2)
    assert (len(empty), len(one), len(two)) == (0, 1, 2)
    gone = two.remove("a")
    assert "a" not in gone
    assert "a" in two
    assert gone.remove("zz") is gone
    assert sorted(two.items()) == [("a", 3), ("b", 2)]


@given(st.lists(st.tuples(st.booleans(), st.integers(0, 40), st.integers())))
def test_behaves_like_a_dict(operations: list[tuple[bool, int, int]]) -> None:
    """Any sequence of sets and removals leaves the same contents as a plain dict."""
    mirror: dict[int, int] = {}
    current: PMap[int, int] = PMap()
    for put, key, value in operations:
        if put:
            mirror[key] = value
            current = current.set(key, value)
        else:
            mirror.pop(key, None)
            current = current.remove(key)
        assert dict(current.items()) == mirror
        assert len(current) == len(mirror)
    keys = list(range(-2, 43))
    assert current.values_of(keys) == [mirror[k] for k in keys if k in mirror]
