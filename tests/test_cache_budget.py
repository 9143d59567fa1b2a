"""The cache's budget: least recently used entries pruned, in-use ones kept, the command."""

import json
import os
import time

import numpy as np
import pytest
from translucent.cache import (
    BUDGET_VARIABLE,
    DEFAULT_BUDGET_BYTES,
    ENTRY_SUFFIX,
    IN_USE_SECONDS,
    Cache,
    budget,
    cache_entries,
    prune,
)
from translucent.errors import InputError

KIB = 1024


def _aged(path, seconds_ago):
    """Set a file's last use ``seconds_ago`` in the past."""
    when = time.time() - seconds_ago
    os.utime(path, (when, when))


def _entries(root, sizes_and_ages):
    """Write entries of the given sizes, each last used the given seconds ago."""
    paths = []
    for index, (size, age) in enumerate(sizes_and_ages):
        key = f"{index:02x}" + "0" * 62
        path = root / "prt" / key[:2] / f"{key}{ENTRY_SUFFIX}"
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_bytes(b"x" * size)
        _aged(path, age)
        paths.append(path)
    return paths


def test_the_budget_setting(monkeypatch):
    monkeypatch.delenv(BUDGET_VARIABLE, raising=False)
    assert budget() == DEFAULT_BUDGET_BYTES
    monkeypatch.setenv(BUDGET_VARIABLE, "0")
    assert budget() is None
    monkeypatch.setenv(BUDGET_VARIABLE, "4096")
    assert budget() == 4096
    for bad in ("-1", "1.5", "ten"):
        monkeypatch.setenv(BUDGET_VARIABLE, bad)
        with pytest.raises(InputError, match=f"{BUDGET_VARIABLE}.*whole number"):
            budget()


def test_the_least_recently_used_go_first_and_entries_in_use_stay(tmp_path):
    old, older, recent, oldest = _entries(tmp_path, [(4 * KIB, 3000), (4 * KIB, 4000),
                                                     (4 * KIB, 1.0), (4 * KIB, 5000)])
    # a lock file and a write in progress are not entries
    writing = tmp_path / "prt" / "00" / f".{'0' * 64}.entry.a1b2c3d4.part.npz"
    (tmp_path / "prt" / "00" / f"{'0' * 64}.lock").write_bytes(b"")
    writing.write_bytes(b"y" * 8 * KIB)
    assert [e.path for e in cache_entries(tmp_path)] == [oldest, older, old, recent]
    removed = prune(9 * KIB, tmp_path)
    assert [e.path for e in removed] == [oldest, older]
    assert old.is_file() and recent.is_file()
    # under a budget no older entry can meet, the entry in use is still kept
    assert [e.path for e in prune(0, tmp_path)] == [old]
    assert recent.is_file() and writing.is_file()
    assert [e.path for e in prune(0, tmp_path, keep_recent=False)] == [recent]
    assert prune(None, tmp_path) == [] and cache_entries(tmp_path) == []


def test_a_read_marks_an_entry_used_and_a_store_keeps_the_budget(tmp_path, monkeypatch):
    cache = Cache("prt", root=tmp_path)
    value = {"table": np.arange(2048, dtype=np.float64)}  # 16 KiB of array
    for key in ("a" * 64, "b" * 64):
        cache.store_object(key, value)
        _aged(cache.path(key, ENTRY_SUFFIX), 10 * IN_USE_SECONDS)
    first, second = (cache.path(k, ENTRY_SUFFIX) for k in ("a" * 64, "b" * 64))
    # the older one is read: now it is the other that was used least recently
    _aged(first, 20 * IN_USE_SECONDS)
    assert cache.load_object("a" * 64) is not None
    assert first.stat().st_mtime > second.stat().st_mtime
    one = first.stat().st_size
    monkeypatch.setenv(BUDGET_VARIABLE, str(2 * one + one // 2))
    cache.store_object("c" * 64, value)  # three entries over a budget of two and a half
    assert first.is_file() and not second.is_file()
    assert cache.path("c" * 64, ENTRY_SUFFIX).is_file()
    assert cache.load_object("b" * 64) is None  # a pruned entry is a miss


def test_the_cache_command_lists_prunes_and_clears(tmp_path, monkeypatch, capsys):
    from translucent.reports.cli import main

    monkeypatch.setenv("TRANSLUCENT_CACHE", str(tmp_path))
    monkeypatch.delenv(BUDGET_VARIABLE, raising=False)
    paths = _entries(tmp_path, [(4 * KIB, 3000), (4 * KIB, 2000), (4 * KIB, 1000)])
    record = tmp_path.parent / "cache.json"
    assert main(["cache", "--json", str(record)]) == 0
    out = capsys.readouterr().out
    assert "prt: 3 entries" in out and "total: 3 entries" in out
    found = json.loads(record.read_text())
    assert found["entries"] == 3 and found["total_bytes"] == 12 * KIB
    assert found["budget_bytes"] == DEFAULT_BUDGET_BYTES and found["removed"] == []
    assert main(["cache", "--prune", "--max-bytes", str(8 * KIB)]) == 0
    assert "removed: 1 entries" in capsys.readouterr().out
    assert not paths[0].exists() and paths[1].exists()
    assert main(["cache", "--clear"]) == 0
    assert cache_entries(tmp_path) == []


@pytest.mark.parametrize("arguments, message", [
    (["--max-bytes", "5"], "--max-bytes = 5: only with --prune"),
    (["--prune", "--max-bytes", "-3"], "--max-bytes = -3: must be an integer >= 0"),
    (["--prune", "--clear"], "not allowed with argument"),
])
def test_bad_cache_arguments_exit_2(arguments, message, tmp_path, monkeypatch, capsys):
    from translucent.reports.cli import main

    monkeypatch.setenv("TRANSLUCENT_CACHE", str(tmp_path))
    paths = _entries(tmp_path, [(KIB, 3000)])
    assert main(["cache", *arguments]) == 2
    assert message in capsys.readouterr().err
    assert paths[0].is_file()


def test_a_bad_budget_is_bad_input_for_the_command(tmp_path, monkeypatch, capsys):
    from translucent.reports.cli import main

    monkeypatch.setenv("TRANSLUCENT_CACHE", str(tmp_path))
    monkeypatch.setenv(BUDGET_VARIABLE, "lots")
    assert main(["cache", "--prune"]) == 2
    assert f"{BUDGET_VARIABLE} = 'lots'" in capsys.readouterr().err
