"""Cache entries that were not made for their key are never served.

A reference entry copied over another key's, one without the pixels' checksum, a
resumable render's state that was edited, holds NaN or belongs to another render, and an
entry path that has become a folder: each is a miss, said on standard error, and made again;
the command ends with exit 0 and the image of its own scene. Every render here is the
16 x 16 sphere at 1 sample per pixel.

A ``TRANSLUCENT_CACHE`` that is no folder the cache can write (a file, a FIFO, a link to
nothing, a loop of links, a folder without permission) is refused by ``translucent cache``
as by every command that writes there: exit 2, one line naming it, nothing changed.
"""

import errno
import json
import os
import tempfile

import numpy as np
import pytest
from hostile import TINY_SPHERE, Made, run_case
from translucent.cache import Cache
from translucent.entries import read_entry, write_entry
from translucent.image import read_exr
from translucent.reports.cli import main

#: A key as the cache makes them (a SHA-256 in hex).
KEY = "c" * 64


@pytest.fixture
def scenes(tmp_path, monkeypatch):
    """Two tiny scenes that differ in their light, in a private cache."""
    monkeypatch.setenv("TRANSLUCENT_CACHE", str(tmp_path / "cache"))
    monkeypatch.chdir(tmp_path)
    (tmp_path / "a.toml").write_text(TINY_SPHERE)
    (tmp_path / "b.toml").write_text(TINY_SPHERE.replace("intensity = 100.0",
                                                         "intensity = 50.0"))
    return tmp_path


def _render(scene, out, *extra) -> int:
    return main(["render", scene, "--spp", "1", "--out", out, *extra])


def _entries(folder, pattern="*.exr") -> set:
    return set((folder / "cache" / "reference").rglob(pattern))


def _made_twice(folder, capsys, spoil) -> tuple:
    """Render a.toml, ``spoil(entry)`` its cache entry, render it again; both images."""
    assert _render("a.toml", "first.exr", "--passes", "2") == 0
    (entry,) = _entries(folder)
    spoil(folder, entry)
    capsys.readouterr()
    assert _render("a.toml", "again.exr", "--passes", "2") == 0
    err = capsys.readouterr().err
    assert f"the cache entry {entry} is not trusted" in err, err
    first, again = read_exr(folder / "first.exr"), read_exr(folder / "again.exr")
    assert again.metadata["scene_hash"] == first.metadata["scene_hash"] == entry.stem
    np.testing.assert_array_equal(again.rgb, first.rgb)  # the same seeds: the same render
    return first, again


def _copied_from_another_key(folder, entry):
    assert _render("b.toml", "b.exr", "--passes", "2") == 0
    (other,) = _entries(folder) - {entry}
    entry.write_bytes(other.read_bytes())


def _without_checksum(folder, entry):
    import OpenEXR

    image = read_exr(entry)  # the same pixels and metadata, as another program writes them
    channels = {"RGB": image.rgb, **{f"variance.{c}": image.variance[..., i]
                                     for i, c in enumerate("RGB")}}
    with OpenEXR.File({"type": OpenEXR.scanlineimage,
                       "translucent:metadata": json.dumps(image.metadata)}, channels) as exr:
        exr.write(str(entry))


def _a_folder(folder, entry):
    entry.unlink()
    (entry / "inside").mkdir(parents=True)


def _progressive(folder, capsys, spoil):
    """A progressive render, its state spoilt, then a render resumed from that state."""
    common = ["--spp", "1", "--target-rse", "0.9"]
    assert _render("a.toml", "first.exr", *common) == 0
    (state,) = _entries(folder, "*.partial.npz")
    spoil(state)
    capsys.readouterr()
    # another target: another final entry, the same state (it is keyed without the target)
    assert _render("a.toml", "again.exr", "--spp", "1", "--target-rse", "0.8") == 0
    err = capsys.readouterr().err
    assert f"the cache entry {state} is not trusted" in err, err
    first, again = read_exr(folder / "first.exr"), read_exr(folder / "again.exr")
    assert again.metadata["passes"] <= 64  # started again, not from a state of 4096 passes
    assert abs(again.rgb.mean() / first.rgb.mean() - 1) < 0.5  # not the edited mean


def _edited_state(state):
    """The mean scaled and the pass count raised with numpy, the entry's JSON kept."""
    with np.load(state) as archive:
        members = {name: archive[name] for name in archive.files}
    meta = json.loads(bytes(members["__entry__"]).decode())
    members["a0"] = members["a0"] * 100
    meta["value"]["count"] = 4096
    members["__entry__"] = np.frombuffer(json.dumps(meta).encode(), np.uint8)
    np.savez(state, **members)


def _rewritten_state(state, change, key=None):
    """The state read and written again as a valid entry (of ``key``) after ``change``."""
    found = read_entry(state, state.name.removesuffix(".partial.npz"))
    change(found)
    with open(state, "wb") as handle:
        write_entry(handle, key or state.name.removesuffix(".partial.npz"), found)


def _nan_state(state):
    _rewritten_state(state, lambda found: found["mean"].__setitem__((0, 0, 0), np.nan))


def _state_of_another_key(state):
    _rewritten_state(state, lambda found: None, key="0" * 64)


#: kind -> how the cache is spoilt and checked
KINDS = {
    "reference copied over another key's": lambda folder, capsys: _made_twice(
        folder, capsys, _copied_from_another_key),
    "reference without the pixels' checksum": lambda folder, capsys: _made_twice(
        folder, capsys, _without_checksum),
    "reference entry that is a folder": lambda folder, capsys: _made_twice(
        folder, capsys, _a_folder),
    "progressive state edited": lambda folder, capsys: _progressive(
        folder, capsys, _edited_state),
    "progressive state holding NaN": lambda folder, capsys: _progressive(
        folder, capsys, _nan_state),
    "progressive state of another render": lambda folder, capsys: _progressive(
        folder, capsys, _state_of_another_key),
}


#: Kinds that render a progressive reference again (5-6 s each): one stays in the fast tier.
SLOW_KINDS = {"progressive state holding NaN", "progressive state of another render"}


@pytest.mark.parametrize("kind", [pytest.param(kind, marks=pytest.mark.slow)
                                  if kind in SLOW_KINDS else kind for kind in sorted(KINDS)])
def test_an_entry_not_made_for_its_key_is_made_again(kind, scenes, capsys):
    KINDS[kind](scenes, capsys)
    assert "Traceback" not in capsys.readouterr().err


def test_a_precomputation_entry_that_is_a_folder_is_a_miss(tmp_path, capsys):
    cache = Cache("method", root=tmp_path)
    cache.store_object("d" * 64, 1)  # the folder is the cache's before the entry is spoilt
    path = cache.path(KEY, ".entry.npz")
    (path / "inside").mkdir(parents=True)
    assert cache.load_object(KEY) is None
    assert cache.store_object(KEY, {"values": np.arange(3.0)}) == path
    assert cache.load_object(KEY)["values"].tolist() == [0.0, 1.0, 2.0]
    assert "is not trusted (it is not a file)" in capsys.readouterr().err


def _loop(path):
    (path.parent / "loop").symlink_to(path)
    path.symlink_to(path.parent / "loop")


def _an_entry_of_a_cache_it_cannot_write(path):
    from translucent.cache import check_folder

    check_folder(path)  # made and marked: the cache's own
    entry = path / "prt" / "ab" / f"{'ab' * 32}.entry.npz"
    entry.parent.mkdir(parents=True)
    entry.write_bytes(b"an entry")


#: what TRANSLUCENT_CACHE names -> (the files made, where it points: "{d}/cache" unless said)
UNUSABLE = {
    "a file": ({"cache": "not a folder"}, "cannot be written (it is a file, not a folder)"),
    "a FIFO": ({"cache": Made(os.mkfifo)}, "it is a FIFO, not a folder"),
    "a link to nothing": ({"cache": Made(lambda path: path.symlink_to(path.parent / "gone"))},
                          "is a symbolic link to"),
    "a loop of links": ({"cache": Made(_loop)}, "it is a loop of symbolic links"),
    "a path through a file": ({"file": "x"}, "a file stands in its path", "{d}/file/cache"),
    "a folder it cannot write": ({"cache": Made(_an_entry_of_a_cache_it_cannot_write)},
                                 "Permission denied"),
}


@pytest.mark.parametrize("arguments", [[], ["--clear"]], ids=["list", "clear"])
@pytest.mark.parametrize("kind", sorted(UNUSABLE))
def test_the_cache_command_refuses_a_cache_it_cannot_use(kind, arguments, tmp_path,
                                                         monkeypatch, capsys):
    files, words, *where = UNUSABLE[kind]
    where = where[0] if where else "{d}/cache"
    mkstemp = tempfile.mkstemp

    def unwritable(*args, **kwargs):
        # what a folder of another user answers (a test run as root is never refused);
        # the marker made before it is in place
        folder = kwargs.get("dir")
        if folder is not None and os.path.isfile(os.path.join(folder, "CACHEDIR.TAG")) \
                and os.path.samefile(folder, tmp_path / "cache"):
            raise PermissionError(errno.EACCES, os.strerror(errno.EACCES), folder)
        return mkstemp(*args, **kwargs)

    if kind == "a folder it cannot write":
        monkeypatch.setattr(tempfile, "mkstemp", unwritable)
    out, err = run_case((["cache", *arguments], files, ["TRANSLUCENT_CACHE", where, words],
                         {"env": {"TRANSLUCENT_CACHE": where}}),
                        tmp_path, monkeypatch, capsys)
    assert err.count("\n") == 1 and out == "", (out, err)
