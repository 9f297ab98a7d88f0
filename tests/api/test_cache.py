"""The content-addressed result cache (api/cache.py): keys, bounds, and one computation for
identical requests in flight."""

from __future__ import annotations

import asyncio

import pytest

from api.cache import ResultCache, answer, cache_key


def test_key_is_canonical_and_content_addressed() -> None:
    a = cache_key("analysis", {"scene": {"b": 1, "a": [1.0, 2]}, "nu": None})
    b = cache_key("analysis", {"nu": None, "scene": {"a": [1.0, 2], "b": 1}})
    assert a == b and len(a) == 64
    assert cache_key("analysis", {"scene": {"a": [1.0, 2.5], "b": 1}, "nu": None}) != a
    assert cache_key("geometry", {"scene": {"b": 1, "a": [1.0, 2]}, "nu": None}) != a


def test_bounded_by_entries_and_bytes_least_recently_used_out() -> None:
    c = ResultCache(max_entries=2, max_bytes=10)
    c.put("a", b"1234")
    c.put("b", b"5678")
    assert c.get("a") == b"1234"  # a is now the most recent
    c.put("c", b"9")
    assert c.get("b") is None and c.get("a") == b"1234" and c.get("c") == b"9"
    c.put("d", b"12345678")  # over 10 bytes with a: a goes
    assert c.get("a") is None and c.get("d") == b"12345678" and c.size <= 10
    c.put("huge", b"x" * 11)  # larger than the whole cache: not kept
    assert c.get("huge") is None
    off = ResultCache(0)
    off.put("a", b"1")
    assert off.get("a") is None


def test_identical_computations_in_flight_run_once_and_share_errors() -> None:
    async def run() -> None:
        c = ResultCache(8)
        calls = 0

        async def compute() -> bytes:
            nonlocal calls
            calls += 1
            await asyncio.sleep(0.05)
            return b"result"

        got = await asyncio.gather(*(answer(c, "k", compute) for _ in range(5)))
        assert calls == 1 and sorted(h for _, h in got) == ["miss"] + ["shared"] * 4
        assert await answer(c, "k", compute) == (b"result", "hit")

        async def fail() -> bytes:
            nonlocal calls
            calls += 1
            await asyncio.sleep(0.05)
            raise ValueError("no")

        calls = 0
        results = await asyncio.gather(*(answer(c, "bad", fail) for _ in range(3)), return_exceptions=True)
        assert calls == 1 and all(isinstance(r, ValueError) for r in results)
        with pytest.raises(ValueError):  # errors are not cached: computed again
            await answer(c, "bad", fail)
        assert calls == 2 and not c.inflight

    asyncio.run(run())
