import numpy as np
from translucent.cache import Cache, cache_dir, content_hash
from translucent.materials import Dipole, measured_medium


def test_hash_is_order_independent_and_content_sensitive():
    assert content_hash({"a": 1, "b": 2}) == content_hash({"b": 2, "a": 1})
    assert content_hash(np.arange(4.0)) != content_hash(np.arange(4.0) + 1e-12)
    assert content_hash(np.arange(4.0)) != content_hash(np.arange(4.0).astype(np.float32))


def test_objects_hash_by_their_cache_key():
    assert content_hash(measured_medium("marble")) == content_hash(
        Dipole(sigma_a=[0.0021, 0.0041, 0.0071], sigma_s_prime=[2.19, 2.62, 3.00], eta=1.5))
    assert content_hash(measured_medium("marble")) != content_hash(measured_medium("apple"))


def test_cache_dir_follows_environment(tmp_path, monkeypatch):
    monkeypatch.setenv("TRANSLUCENT_CACHE", str(tmp_path / "c"))
    assert cache_dir() == tmp_path / "c"


def test_pickle_round_trip_and_miss(tmp_path):
    cache = Cache("unit", root=tmp_path)
    key = content_hash("x")
    assert cache.load_pickle(key) is None
    cache.store_pickle(key, {"a": np.arange(3)})
    assert np.array_equal(cache.load_pickle(key)["a"], np.arange(3))
    # a corrupt entry is a miss, not a crash
    cache.path(key, ".pkl").write_bytes(b"garbage")
    assert cache.load_pickle(key) is None


def test_private_cache_is_empty_then_removed_and_restores_the_setting(tmp_path, monkeypatch):
    from translucent.cache import cache_dir, private_cache

    monkeypatch.setenv("TRANSLUCENT_CACHE", str(tmp_path))
    with private_cache(prefix="t-") as folder:
        assert cache_dir() == folder and folder.name.startswith("t-")
        assert not any(folder.iterdir())
        (folder / "entry").write_text("x")
    assert not folder.exists()
    assert cache_dir() == tmp_path


def test_a_cache_that_cannot_be_written_names_translucent_cache(tmp_path, monkeypatch):
    import pytest
    from translucent.errors import InputError

    a_file = tmp_path / "a_file"
    a_file.write_text("keep me")
    monkeypatch.setenv("TRANSLUCENT_CACHE", str(a_file))
    with pytest.raises(InputError, match=r"TRANSLUCENT_CACHE = '.*a_file': the cache cannot "
                                         r"be written"):
        Cache("unit").store_pickle(content_hash("x"), 1)
    assert a_file.read_text() == "keep me"


def test_entries_over_the_limit_are_not_written_and_the_setting_is_restored(tmp_path,
                                                                          monkeypatch):
    from translucent.cache import ENTRY_LIMIT_VARIABLE, entry_limit, limited_entries

    monkeypatch.delenv(ENTRY_LIMIT_VARIABLE, raising=False)
    cache = Cache("unit", root=tmp_path)
    small, large = content_hash("small"), content_hash("large")
    with limited_entries(1000):
        assert entry_limit() == 1000
        assert cache.store_pickle(small, np.zeros(10), nbytes=80) is not None
        assert cache.store_pickle(large, np.zeros(200), nbytes=1600) is None
        assert cache.store_pickle(content_hash("unsized"), np.zeros(200)) is not None
        with limited_entries(None):
            assert entry_limit() is None
        assert entry_limit() == 1000
    assert entry_limit() is None
    assert cache.load_pickle(small) is not None
    assert cache.load_pickle(large) is None
    assert not cache.path(large, ".pkl").exists()
    assert cache.store_pickle(large, np.zeros(200), nbytes=1600) is not None


def test_a_bad_entry_limit_names_the_variable(monkeypatch):
    import pytest
    from translucent.cache import ENTRY_LIMIT_VARIABLE, entry_limit, limited_entries
    from translucent.errors import InputError

    for value in ("-1", "1e9", "lots"):
        monkeypatch.setenv(ENTRY_LIMIT_VARIABLE, value)
        with pytest.raises(InputError, match=rf"{ENTRY_LIMIT_VARIABLE} = '{value}'"):
            entry_limit()
    with pytest.raises(InputError, match="max_bytes = -5"):
        with limited_entries(-5):
            pass
