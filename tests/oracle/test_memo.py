"""The result memo: values by content key, and whether one is stored without reading it."""
from mpgspec.oracle.cache import Memo, ResultStore


def test_has_answers_without_reading_and_agrees_with_get(tmp_path):
    memo = Memo(ResultStore(tmp_path / "results.sqlite"))
    key, other = memo.key("robust", 1, "a"), memo.key("robust", 1, "b")
    assert not memo.has(key) and memo.get(key) is None
    memo.put(key, {"edges": [1, 2.5, None]})
    assert memo.has(key) and memo.get(key) == {"edges": [1, 2.5, None]}
    assert not memo.has(other)
