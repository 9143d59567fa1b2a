import numpy as np
from translucent.cache import ENTRY_SUFFIX, Cache, cache_dir, content_hash
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


def test_object_round_trip_and_miss(tmp_path):
    cache = Cache("unit", root=tmp_path)
    key = content_hash("x")
    assert cache.load_object(key) is None
    cache.store_object(key, {"a": np.arange(3)})
    assert np.array_equal(cache.load_object(key)["a"], np.arange(3))
    # a corrupt entry is a miss, not a crash
    cache.path(key, ENTRY_SUFFIX).write_bytes(b"garbage")
    assert cache.load_object(key) is None


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
        Cache("unit").store_object(content_hash("x"), 1)
    assert a_file.read_text() == "keep me"


def test_entries_over_the_limit_are_not_written_and_the_setting_is_restored(tmp_path,
                                                                          monkeypatch):
    from translucent.cache import ENTRY_LIMIT_VARIABLE, entry_limit, limited_entries

    monkeypatch.delenv(ENTRY_LIMIT_VARIABLE, raising=False)
    cache = Cache("unit", root=tmp_path)
    small, large = content_hash("small"), content_hash("large")
    with limited_entries(1000):
        assert entry_limit() == 1000
        assert cache.store_object(small, np.zeros(10), nbytes=80) is not None
        assert cache.store_object(large, np.zeros(200), nbytes=1600) is None
        assert cache.store_object(content_hash("unsized"), np.zeros(200)) is not None
        with limited_entries(None):
            assert entry_limit() is None
        assert entry_limit() == 1000
    assert entry_limit() is None
    assert cache.load_object(small) is not None
    assert cache.load_object(large) is None
    assert not cache.path(large, ".pkl").exists()
    assert cache.store_object(large, np.zeros(200), nbytes=1600) is not None


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


class _RunsCode:
    """A pickle that runs code when loaded: what a crafted cache entry would hold."""

    def __init__(self, marker):
        self.marker = str(marker)

    def __reduce__(self):
        return (open, (self.marker, "w"))


def test_no_pickle_is_ever_loaded_from_the_cache(tmp_path, capsys):
    import io
    import pickle

    cache = Cache("radiosity", root=tmp_path)
    marker = tmp_path / "the_code_ran"
    path = cache.path("k" * 64, ENTRY_SUFFIX)
    path.parent.mkdir(parents=True)
    # a crafted pickle under the entry's name, and an npz whose member is a pickled object
    path.write_bytes(pickle.dumps(_RunsCode(marker)))
    assert cache.load_object("k" * 64) is None
    buffer = io.BytesIO()
    np.savez(buffer, __entry__=np.array([_RunsCode(marker)], dtype=object), a0=np.zeros(2))
    path.write_bytes(buffer.getvalue())
    assert cache.load_object("k" * 64) is None
    assert not marker.exists()
    assert "is not trusted" in capsys.readouterr().err
    # the check can fail: unpickled as such, the same bytes run the code
    pickle.loads(pickle.dumps(_RunsCode(marker))).close()
    assert marker.exists()


def test_an_entry_naming_a_class_outside_the_package_is_a_miss(tmp_path, capsys):
    import json

    cache = Cache("prt", root=tmp_path)
    path = cache.store_object("d" * 64, {"x": 1})
    with np.load(path, allow_pickle=False) as archive:
        meta = json.loads(bytes(archive["__entry__"]).decode())
    meta["value"] = {"@object": "subprocess.Popen", "state": {"args": "touch x"}}
    np.savez(path, __entry__=np.frombuffer(json.dumps(meta).encode(), dtype=np.uint8))
    assert cache.load_object("d" * 64) is None
    assert "subprocess.Popen" in capsys.readouterr().err


def test_an_altered_or_truncated_entry_is_a_miss(tmp_path, capsys):
    cache = Cache("prt", root=tmp_path)
    path = cache.store_object("a" * 64, {"pixels": np.arange(1000.0)})
    assert cache.load_object("a" * 64)["pixels"].sum() == np.arange(1000.0).sum()
    data = bytearray(path.read_bytes())
    offset = data.find(np.arange(1000.0).tobytes()[800:808])
    data[offset] ^= 0xFF  # one byte of the array changed
    path.write_bytes(bytes(data))
    assert cache.load_object("a" * 64) is None
    path.write_bytes(bytes(data[:40]))
    assert cache.load_object("a" * 64) is None
    assert capsys.readouterr().err.count("is not trusted") == 1  # said once


def test_an_entry_under_another_key_is_a_miss(tmp_path):
    cache = Cache("prt", root=tmp_path)
    path = cache.store_object("b" * 64, [1, 2, 3])
    other = cache.path("e" * 64, ENTRY_SUFFIX)
    other.parent.mkdir(parents=True, exist_ok=True)
    other.write_bytes(path.read_bytes())
    assert cache.load_object("b" * 64) == [1, 2, 3]
    assert cache.load_object("e" * 64) is None


def test_a_value_that_cannot_be_stored_is_kept_out(tmp_path):
    cache = Cache("prt", root=tmp_path)
    assert cache.store_object("f" * 64, {"call": print}) is None
    assert cache.load_object("f" * 64) is None
    assert not any(p.is_file() for p in (tmp_path / "prt").rglob("*"))


def test_load_or_make_makes_an_entry_once_for_concurrent_callers(tmp_path):
    import threading
    import time

    made = []

    def make():
        made.append(threading.get_ident())
        time.sleep(0.5)
        return {"value": 42}

    answers = []

    def ask():
        answers.append(Cache("test", root=tmp_path).load_or_make("cd" * 32, make))

    threads = [threading.Thread(target=ask) for _ in range(3)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join(timeout=60)
    assert len(made) == 1
    assert sorted(flag for _, flag in answers) == [False, False, True]
    assert all(value == {"value": 42} for value, _ in answers)
    # a stored value the caller refuses is a miss: made again
    value, again = Cache("test", root=tmp_path).load_or_make(
        "cd" * 32, lambda: {"value": 7}, valid=lambda stored: stored["value"] == 7)
    assert again and value == {"value": 7}
