"""The cache removes only what it made, and uses only a folder of its own.

A folder that holds other files (a user's, a scene's) is refused before anything is
written or removed there; an empty one, or an older cache holding nothing but the cache's
own files, is adopted; inside the cache only files named and placed as entries are ever
pruned or cleared. A disk that is full while an entry is written is a warning.
"""

import errno
import os
import tempfile
import time
from pathlib import Path

import numpy as np
import pytest
from translucent.cache import BUDGET_VARIABLE, ENTRY_SUFFIX, Cache, cache_entries, prune
from translucent.errors import InputError
from translucent.reports.cli import main

#: A key as the cache makes them (a SHA-256 in hex), and another in the same folder.
KEY, OTHER = "ab" + "0" * 62, "ab" + "1" * 62


def _aged(path, seconds=3600.0):
    """Make ``path`` look last used ``seconds`` ago: long out of use, first to be pruned."""
    when = time.time() - seconds
    os.utime(path, (when, when), follow_symlinks=False)


def _entry(root, key=KEY, suffix=ENTRY_SUFFIX, namespace="prt", shard=None):
    """Write an old file named and placed as the cache's entries are (``shard``: elsewhere)."""
    path = root / namespace / (shard or key[:2]) / f"{key}{suffix}"
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_bytes(b"x" * 1024)
    _aged(path)
    return path


def _snapshot(folder) -> dict:
    """Every path under ``folder`` with its bytes (files) or its link target."""
    return {str(path.relative_to(folder)): os.readlink(path) if path.is_symlink()
            else path.read_bytes() if path.is_file() else None
            for path in sorted(folder.rglob("*"))}


@pytest.fixture
def users_folder(tmp_path, monkeypatch):
    """A folder of a user's files, long unused, named by TRANSLUCENT_CACHE; a tiny budget."""
    folder = tmp_path / "work"
    for name, text in {"scene.toml": "[camera]\n", "notes.txt": "keep me",
                       "photos/a.jpg": "jpeg"}.items():
        (folder / name).parent.mkdir(parents=True, exist_ok=True)
        (folder / name).write_text(text)
        _aged(folder / name)
    monkeypatch.setenv("TRANSLUCENT_CACHE", str(folder))
    monkeypatch.setenv(BUDGET_VARIABLE, "1")
    return folder


def test_a_store_into_a_users_folder_is_refused_before_it_writes_or_prunes(users_folder):
    before = _snapshot(users_folder)
    message = f"TRANSLUCENT_CACHE = '{users_folder}': is not a translucent cache"
    with pytest.raises(InputError, match=message):
        Cache("prt").store_object(KEY, {"a": np.arange(100.0)})
    made = []
    with pytest.raises(InputError, match=message):  # refused before the work, not after
        Cache("prt").load_or_make(KEY, lambda: made.append(1) or {"a": 1})
    assert made == []
    assert _snapshot(users_folder) == before


@pytest.mark.parametrize("arguments", [[], ["--clear"], ["--prune", "--max-bytes", "1"]])
def test_the_cache_command_refuses_a_users_folder(arguments, users_folder, capsys):
    before = _snapshot(users_folder)
    assert main(["cache", *arguments]) == 2
    out, err = capsys.readouterr()
    assert err.count("\n") == 1 and "Traceback" not in err, err
    assert f"TRANSLUCENT_CACHE = '{users_folder}': is not a translucent cache" in err
    assert _snapshot(users_folder) == before


def _users_file_at_the_root(root):
    (root / "notes.txt").write_text("keep me")


def _users_file_beside_entries(root):
    (root / "prt" / "ab" / "notes.txt").write_text("keep me")


def _entry_in_another_folder(root):
    _entry(root, OTHER, shard="cd")


def _link_named_as_an_entry(root):
    target = root.parent / "elsewhere.exr"
    target.write_text("keep me")
    (root / "prt" / "ab" / f"{OTHER}.exr").symlink_to(target)


def _tag_of_another_program(root):
    (root / "CACHEDIR.TAG").write_text("Signature: 8a477f597d28d172789f06886806bc55\n"
                                       "# This file is a cache directory tag created by cargo.\n")


@pytest.mark.parametrize("spoil", [_users_file_at_the_root, _users_file_beside_entries,
                                   _entry_in_another_folder, _link_named_as_an_entry,
                                   _tag_of_another_program], ids=lambda spoil: spoil.__name__)
def test_a_folder_holding_more_than_cache_entries_is_not_adopted(spoil, tmp_path):
    root = tmp_path / "cache"
    _entry(root)
    spoil(root)
    before = _snapshot(root)
    with pytest.raises(InputError, match="is not a translucent cache"):
        prune(0, root, keep_recent=False)
    assert _snapshot(root) == before  # its entries too: nothing is removed, nothing marked


def test_an_empty_or_new_folder_is_made_the_caches_own(tmp_path):
    from translucent.cache import MARKER_NAME, check_folder

    empty, new = tmp_path / "empty", tmp_path / "new" / "deeper"
    empty.mkdir()
    for folder in (empty, new):
        assert check_folder(folder) == folder
        marker = (folder / MARKER_NAME).read_text()
        # a cache directory tag: backup tools skip the folder
        assert marker.startswith("Signature: 8a477f597d28d172789f06886806bc55\n")
        assert [path.name for path in folder.iterdir()] == [MARKER_NAME]
    (empty / "notes.txt").write_text("the user's, in a folder the cache owns")
    assert check_folder(empty) == empty  # marked: the cache's, whatever else is put there


def test_a_folder_another_process_marks_while_it_is_checked_is_the_caches(tmp_path,
                                                                       monkeypatch):
    # two processes making one new cache: the other's marker lands between this one's
    # look for the marker and its look for foreign files (seen in CI with three threads)
    from translucent import cache
    from translucent.cache import MARKER_NAME, check_folder

    folder = tmp_path / "shared"
    folder.mkdir()
    looked = cache._first_foreign

    def marked_meanwhile(root):
        cache._mark(root)
        return looked(root)

    monkeypatch.setattr(cache, "_first_foreign", marked_meanwhile)
    assert check_folder(folder) == folder
    assert [path.name for path in folder.iterdir()] == [MARKER_NAME]


def test_an_older_cache_without_the_marker_is_adopted(tmp_path, monkeypatch, capsys):
    from translucent.cache import MARKER_NAME

    root = tmp_path / "cache"
    entries = [_entry(root), _entry(root, OTHER, ".exr", "reference"),
               _entry(root, KEY, ".partial.npz", "reference"), _entry(root, OTHER, ".pkl")]
    companions = [_entry(root, KEY, ".lock"),  # left by a killed process
                  _entry(root, f".{OTHER}.entry.a1B2_c3d", ".part.npz", shard="ab")]  # cut short
    (root / "radiosity" / "0f").mkdir(parents=True)
    monkeypatch.setenv("TRANSLUCENT_CACHE", str(root))
    assert main(["cache"]) == 0
    assert "total: 4 entries" in capsys.readouterr().out
    assert (root / MARKER_NAME).is_file()
    assert main(["cache", "--clear"]) == 0
    assert not any(path.exists() for path in entries)
    assert all(path.exists() for path in companions)


def test_inside_the_cache_only_its_entries_are_pruned_or_cleared(tmp_path, monkeypatch,
                                                                 capsys):
    root = tmp_path / "cache"
    Cache("prt", root=root).store_object(OTHER, {"a": np.arange(10.0)})  # marks the folder
    stored = Cache("prt", root=root).path(OTHER, ENTRY_SUFFIX)
    _aged(stored)
    entries = [stored, _entry(root), _entry(root, "cd" + "2" * 62, ".exr", "reference")]
    outside = tmp_path / "users"
    outside.mkdir()
    users = {outside / "photo.exr": "keep me", root / "notes.txt": "keep me",
             root / "prt" / "readme.txt": "keep me", root / "prt" / "ab" / "notes.npz": "keep"}
    for path, text in users.items():
        path.write_text(text)
        _aged(path)
    kept = [_entry(root, "ef" + "3" * 62, shard="00"),  # not in its key's folder
            _entry(root, "ab" + "A" * 62),  # not a key the cache makes (upper case)
            root / "prt" / "ab" / f"{'ab' + '4' * 62}.exr",  # a link, not the cache's file
            root / "linked"]  # a namespace that is a link to a user's folder
    kept[2].symlink_to(outside / "photo.exr")
    kept[3].symlink_to(outside)
    (outside / "ab").mkdir()
    users[_entry(outside, namespace="", shard="ab")] = "x" * 1024  # reached only via the link
    assert sorted(entry.path for entry in cache_entries(root)) == sorted(entries)
    monkeypatch.setenv("TRANSLUCENT_CACHE", str(root))
    assert main(["cache", "--clear"]) == 0
    assert "removed: 3 entries" in capsys.readouterr().out
    assert not any(path.exists() for path in entries)
    assert all(os.path.lexists(path) for path in kept)
    assert all(path.read_text() == text for path, text in users.items())


def test_an_entry_the_cache_may_not_remove_is_one_line_exit_2(tmp_path, monkeypatch, capsys):
    root = tmp_path / "cache"
    Cache("prt", root=root).store_object(KEY, {"a": np.arange(10.0)})
    locked = Cache("prt", root=root).path(KEY, ENTRY_SUFFIX)
    unlink = Path.unlink

    def refused(path, missing_ok=False):
        # what unlink says in a folder of another user (a test run as root is never refused)
        if path == locked:
            raise PermissionError(errno.EACCES, os.strerror(errno.EACCES), str(path))
        return unlink(path, missing_ok=missing_ok)

    monkeypatch.setattr(Path, "unlink", refused)
    monkeypatch.setenv("TRANSLUCENT_CACHE", str(root))
    assert main(["cache", "--clear"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Traceback" not in err, err
    assert f"TRANSLUCENT_CACHE = '{root}': cannot remove the entry {locked} (Permission " \
           "denied)" in err
    assert locked.is_file()


def _full(code):
    """A ``write_entry`` that writes part of the entry, then finds the disk full."""
    def write(handle, key, value, progress=None):
        handle.write(b"PK\x03\x04" + b"\0" * 4096)
        raise OSError(code, os.strerror(code))
    return write


@pytest.mark.parametrize("code", [errno.ENOSPC, errno.EDQUOT], ids=errno.errorcode.get)
def test_a_full_disk_is_a_warning_and_leaves_no_partial_entry(code, tmp_path, monkeypatch,
                                                              capsys):
    from translucent import entries

    monkeypatch.setattr(entries, "write_entry", _full(code))
    cache = Cache("prt", root=tmp_path / "cache")
    value, made = cache.load_or_make(KEY, lambda: {"a": 42})
    assert made and value == {"a": 42}  # the result still comes
    assert cache.store_object(OTHER, {"a": 1}) is None
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "warning" in err and os.strerror(code) in err, err
    assert str(cache.path(KEY, ENTRY_SUFFIX)) in err
    assert not [path for path in cache.folder.rglob("*") if not path.is_dir()]


def test_no_room_for_the_temporary_file_is_a_warning_too(tmp_path, monkeypatch, capsys):
    cache = Cache("prt", root=tmp_path / "cache")
    target = cache.path(KEY, ENTRY_SUFFIX)
    mkstemp = tempfile.mkstemp

    def full(*args, **kwargs):
        if str(kwargs.get("prefix", "")).startswith(f".{KEY}"):
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        return mkstemp(*args, **kwargs)

    monkeypatch.setattr(tempfile, "mkstemp", full)
    assert cache.store_object(KEY, {"a": np.arange(10.0)}) is None
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and f"cannot store {target}" in err, err
    assert not [path for path in cache.folder.rglob("*") if not path.is_dir()]


def test_storing_turns_no_room_into_the_warning_and_other_failures_into_input_errors(
        tmp_path, capsys):
    from translucent.atomic import atomic_path

    cache = Cache("reference", root=tmp_path / "cache")
    target = cache.make_room(cache.path(KEY, ".exr"))
    with cache.storing(target), atomic_path(target) as tmp:  # what a writer of files does
        tmp.write_bytes(b"half an image")
        raise OSError(errno.EDQUOT, os.strerror(errno.EDQUOT))
    assert f"cannot store {target} ({os.strerror(errno.EDQUOT)})" in capsys.readouterr().err
    assert not [path for path in cache.folder.rglob("*") if not path.is_dir()]
    with pytest.raises(InputError, match="TRANSLUCENT_CACHE = .*the cache cannot be written"):
        with cache.storing(target):
            raise PermissionError(errno.EACCES, os.strerror(errno.EACCES), str(target))
