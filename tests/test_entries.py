"""Cache entries without pickle: what goes in comes out, and nothing else runs."""

import io
import pathlib

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import sparse
from translucent.entries import EntryError, read_entry, write_entry
from translucent.fast.base import StageLog
from translucent.image import Image


def _round_trip(value, key="k"):
    buffer = io.BytesIO()
    write_entry(buffer, key, value)
    buffer.seek(0)
    return read_entry(buffer, key)


_LEAVES = st.one_of(st.none(), st.booleans(), st.integers(-2**70, 2**70),
                    st.floats(allow_nan=False), st.text(max_size=8), st.binary(max_size=8))
_VALUES = st.recursive(_LEAVES, lambda inner: st.one_of(
    st.lists(inner, max_size=4), st.tuples(inner, inner),
    st.dictionaries(st.text(max_size=5), inner, max_size=4)), max_leaves=20)


@settings(max_examples=150, deadline=None)
@given(_VALUES)
def test_plain_values_come_back_equal(value):
    assert _round_trip(value) == value


@settings(max_examples=50, deadline=None)
@given(st.sampled_from(["float32", "float64", "int8", "uint32", "bool", "complex128"]),
       st.lists(st.integers(0, 5), min_size=0, max_size=3))
def test_arrays_come_back_bit_for_bit(dtype, shape):
    array = (np.random.default_rng(1).random(shape) * 7).astype(dtype)
    back = _round_trip({"a": array})["a"]
    assert back.dtype == array.dtype and back.shape == array.shape
    assert np.array_equal(back, array)


def test_the_package_objects_sparse_matrices_and_special_numbers_come_back():
    log = StageLog(skipped=["x"], seconds={"a": 1.0}, notes={"n": (1, 2), 3: "int key"})
    image = Image(np.ones((2, 3, 3), np.float32), metadata={"producer": "prt"})
    matrix = sparse.random(5, 7, density=0.3, format="csr", random_state=2)
    back = _round_trip({"log": log, "image": image, "F": matrix, "inf": float("inf"),
                        "path": pathlib.Path("/tmp/x"), "set": {1, 2}, "np": np.float32(2.5)})
    assert back["log"] == log and back["log"].notes[3] == "int key"
    assert np.array_equal(back["image"].rgb, image.rgb) and back["image"].metadata == \
        image.metadata
    assert (back["F"] != matrix).nnz == 0 and back["F"].format == "csr"
    assert back["inf"] == float("inf") and back["path"] == pathlib.Path("/tmp/x")
    assert back["set"] == {1, 2} and back["np"] == np.float32(2.5)


@pytest.mark.parametrize("value, words", [
    ({"f": print}, "builtin_function_or_method"),
    (np.array([object()], dtype=object), "Python objects"),
    (io.BytesIO(), "_io.BytesIO"),
])
def test_what_cannot_be_stored_is_refused(value, words):
    with pytest.raises(EntryError, match=words):
        write_entry(io.BytesIO(), "k", value)


def test_an_entry_of_another_key_is_refused():
    buffer = io.BytesIO()
    write_entry(buffer, "first", [1])
    buffer.seek(0)
    with pytest.raises(EntryError, match="another key"):
        read_entry(buffer, "second")


def test_an_entry_naming_a_moved_module_is_a_miss_and_made_again(tmp_path, monkeypatch):
    # a precomputation stored before its module moved (fast/brdf_pca_transfer.py is now
    # fast/brdf_pca/transfer.py) names a module that is gone: read as a miss, made again
    from translucent.cache import Cache
    from translucent.fast.base import load_or_precompute

    monkeypatch.setenv("TRANSLUCENT_CACHE", str(tmp_path))
    with monkeypatch.context() as moved:
        moved.setattr(StageLog, "__module__", "translucent.fast.brdf_pca_transfer")
        Cache("moved").store_object("key", StageLog(skipped=["old layout"]))
        buffer = io.BytesIO()
        write_entry(buffer, "key", StageLog())
    buffer.seek(0)
    with pytest.raises(EntryError, match="does not exist"):
        read_entry(buffer, "key")
    assert Cache("moved").load_object("key") is None
    made = []
    value, fresh = load_or_precompute("moved", "key", lambda: made.append(1) or StageLog(),
                                      what="a test entry", log_of=lambda log: log)
    assert fresh and made == [1] and value.skipped == [] and value.notes["cache"] == "miss"
    again, fresh = load_or_precompute("moved", "key", lambda: made.append(2) or StageLog(),
                                      what="a test entry", log_of=lambda log: log)
    assert not fresh and made == [1] and again.notes["cache"] == "hit"
