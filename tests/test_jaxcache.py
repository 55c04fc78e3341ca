"""The caches check what they load: sealed entries, damage repaired and said once, no lock to hang on."""

import fcntl
import os
import time

import pytest

from jaxlimb import _jaxcache as jc
from jaxlimb.errors import CacheRepairWarning


@pytest.fixture(autouse=True)
def _fresh_warnings(monkeypatch):
    monkeypatch.setattr(jc, "_WARNED", set())  # said once per process: each test starts a "process"


def test_seal_round_trip_and_every_single_bit_flip_is_caught():
    payload = bytes(range(256)) * 4
    sealed = jc.seal(payload)
    assert jc.unseal(sealed) == payload
    for i in range(0, len(sealed), 7):  # header and payload bytes alike
        for bit in (0, 3, 7):
            damaged = bytearray(sealed)
            damaged[i] ^= 1 << bit
            assert jc.unseal(bytes(damaged)) is None
    assert jc.unseal(sealed[:-1]) is None and jc.unseal(b"") is None and jc.unseal(payload) is None
    assert jc.unseal(sealed, versions=b"jax=0.0.0;jaxlib=0.0.0") is None  # another JAX's entry


def test_damaged_entry_is_deleted_missed_and_said_once(tmp_path):
    cache = jc.CheckedCache(tmp_path)
    cache.put("k1", b"program one")
    cache.put("k2", b"program two")
    assert cache.get("k1") == b"program one" and cache.get("missing") is None
    for key in ("k1", "k2"):
        p = tmp_path / f"{key}-cache"
        data = bytearray(p.read_bytes())
        data[-3] ^= 0x10
        p.write_bytes(bytes(data))
    with pytest.warns(CacheRepairWarning, match="k1-cache failed its check") as record:
        assert cache.get("k1") is None
        assert cache.get("k2") is None  # a second damaged entry: no second message
    assert len(record) == 1
    assert not (tmp_path / "k1-cache").exists() and not (tmp_path / "k2-cache").exists()
    cache.put("k1", b"program one")  # compiled again, stored again
    assert cache.get("k1") == b"program one"


def test_junk_atime_files_and_a_stale_lock_neither_stop_nor_slow_the_cache(tmp_path):
    """Junk ``*-cache`` files, orphan or deleted JAX ``-atime`` files and JAX's ``.lockfile`` held by a holder
    that never lets go (a stopped process) are what stopped JAX's own cache storing, or made every access wait
    10 s: the checked cache takes no lock and keeps storing."""
    (tmp_path / "junk-cache").write_bytes(os.urandom(1000))
    (tmp_path / "orphan-atime").write_bytes(b"\0" * 8)
    fd = os.open(tmp_path / ".lockfile", os.O_RDWR | os.O_CREAT)
    fcntl.flock(fd, fcntl.LOCK_EX)  # as a stopped holder would: never released during the test
    try:
        cache = jc.CheckedCache(tmp_path)
        t0 = time.perf_counter()
        for i in range(20):
            cache.put(f"key{i}", b"x" * 100)
            assert cache.get(f"key{i}") == b"x" * 100
        assert time.perf_counter() - t0 < 2.0
    finally:
        os.close(fd)


def test_least_recently_used_entries_are_evicted_beyond_the_limit(tmp_path):
    cache = jc.CheckedCache(tmp_path, max_bytes=10_000)
    for i in range(5):
        cache.put(f"k{i}", bytes(1500))
        os.utime(tmp_path / f"k{i}-cache", ns=(i * 10**9, i * 10**9))  # k0 oldest
    cache.get("k0")  # a hit makes k0 the most recently used
    for i in range(5, 8):
        cache.put(f"k{i}", bytes(1500))
    left = sorted(p.name for p in tmp_path.glob("*-cache"))
    assert "k0-cache" in left and "k1-cache" not in left
    assert sum(p.stat().st_size for p in tmp_path.glob("*-cache")) <= 10_000


def test_a_cache_that_cannot_be_written_is_skipped_with_one_warning(tmp_path):
    blocker = tmp_path / "a-file"
    blocker.write_text("not a directory")
    cache = jc.CheckedCache(blocker / "jax")
    with pytest.warns(CacheRepairWarning, match="cannot be written"):
        cache.put("k", b"v")
        cache.put("k2", b"v")
    assert cache.get("k") is None


def test_cache_root_that_is_a_file_runs_without_the_cache(tmp_path, monkeypatch):
    blocker = tmp_path / "a-file"
    blocker.write_text("not a directory")
    monkeypatch.delenv("JAXLIMB_CACHE_DIR", raising=False)
    monkeypatch.delenv("JAX_COMPILATION_CACHE_DIR", raising=False)
    monkeypatch.setenv("JAXLIMB_CACHE", str(blocker))
    with pytest.warns(CacheRepairWarning, match="cannot be used"):
        assert jc.enable_compile_cache() is None
