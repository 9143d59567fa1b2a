import os

import pytest
from translucent.backend import VARIANT_ORDER, backend_facts, find_libllvm, mitsuba
from translucent.reports.cli import main


def test_a_libllvm_of_version_16_or_newer_is_found():
    path = find_libllvm()
    assert path is not None and os.path.isfile(path)


def test_variant_is_the_first_that_works():
    mi = mitsuba()
    assert mi.variant() in VARIANT_ORDER
    # no GPU on the test machines: the LLVM variant must be usable there
    if mi.variant() != "cuda_ad_rgb":
        assert mi.variant() == "llvm_ad_rgb"


def test_facts_name_everything_doctor_prints():
    facts = backend_facts()
    assert set(facts) >= {"python", "mitsuba", "drjit", "variant", "libllvm", "gpu"}


def test_doctor_command(capsys):
    assert main(["doctor"]) == 0
    out = capsys.readouterr().out
    assert "variant" in out and "libllvm" in out and "cache" in out


def test_unknown_command_is_a_usage_error(capsys):
    assert main(["no-such-command"]) == 2


def test_bad_variant_override(monkeypatch):
    import translucent.backend as backend

    monkeypatch.setenv("TRANSLUCENT_VARIANT", "no_such_variant")
    backend.mitsuba.cache_clear()
    try:
        with pytest.raises(ValueError, match="TRANSLUCENT_VARIANT = 'no_such_variant'"):
            backend.mitsuba()
    finally:
        monkeypatch.delenv("TRANSLUCENT_VARIANT")
        backend.mitsuba.cache_clear()
        backend.mitsuba()


def test_importing_drjit_after_the_package_uses_the_found_libllvm():
    import subprocess
    import sys

    env = {k: v for k, v in os.environ.items() if k != "DRJIT_LIBLLVM_PATH"}
    code = ("import translucent, drjit as dr; from drjit.llvm import Float; "
            "print(dr.maximum(Float([1, 2, 3]), 2.0))")
    done = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True,
                          timeout=120)
    assert done.returncode == 0, done.stderr
    assert "[2, 2, 3]" in done.stdout
