"""The base install alone (no extra) compares images and runs the pytest plugin.

A fresh virtual environment gets the suite without its extras (``pip install .``, from
the package index or the machine's cache: slow tier) and runs ``translucent compare`` and
the plugin on committed EXRs; a command that needs an extra says which one, exit 2.
"""

import shutil
import subprocess
import textwrap
import venv
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
REFERENCE = ROOT / "reference" / "data" / "sphere.exr"
MODEL = ROOT / "reference" / "data" / "model" / "sphere.dipole.exr"


@pytest.fixture(scope="module")
def base_install(tmp_path_factory):
    folder = tmp_path_factory.mktemp("base_venv")
    venv.create(folder / "venv", with_pip=True)
    python = folder / "venv" / "bin" / "python"
    # built from a copy: setuptools builds in the source tree (build/, *.egg-info)
    source = folder / "source"
    anywhere = shutil.ignore_patterns(".git", ".tox", "build", "*.egg-info", "__pycache__",
                                      ".hypothesis")

    def ignored(path, names):  # a report folder at the root, not reports/report/
        extra = {"report"} if Path(path).resolve() == ROOT else set()
        return set(anywhere(path, names)) | (extra & set(names))

    shutil.copytree(ROOT, source, ignore=ignored)
    subprocess.run([python, "-m", "pip", "install", "--quiet", str(source), "pytest"],
                   check=True, capture_output=True, timeout=1200)
    return folder / "venv"


@pytest.mark.slow
def test_the_base_install_has_no_renderer_and_compares_images(base_install, tmp_path):
    python = base_install / "bin" / "python"
    listed = subprocess.run([python, "-m", "pip", "list", "--format", "freeze"],
                            capture_output=True, text=True, check=True).stdout.lower()
    for absent in ("mitsuba", "drjit", "numba", "llvmlite", "dask", "emcee"):
        assert f"{absent}==" not in listed, absent
    command = base_install / "bin" / "translucent"
    compared = subprocess.run([command, "compare", REFERENCE, MODEL, "--maps", tmp_path,
                               "--metric", "relative_mse", "--max", "0.01"],
                              capture_output=True, text=True)
    assert compared.returncode == 0, compared.stderr
    assert "relative_mse" in compared.stdout and list(tmp_path.glob("*_flip.png"))
    rendered = subprocess.run([command, "render", "sphere"], capture_output=True, text=True)
    assert rendered.returncode == 2
    assert "translucent[render]" in rendered.stderr and "Traceback" not in rendered.stderr


@pytest.mark.slow
def test_the_plugin_runs_in_the_base_install(base_install, tmp_path):
    (tmp_path / "test_images.py").write_text(textwrap.dedent(f'''
        import pytest
        from translucent.reports.pytest_plugin import assert_image_close

        def test_the_model_reference_is_close():
            assert_image_close({str(MODEL)!r}, {str(REFERENCE)!r}, "relative_mse", max=0.01)

        def test_a_tight_bound_fails():
            with pytest.raises(AssertionError):
                assert_image_close({str(MODEL)!r}, {str(REFERENCE)!r}, "relative_mse",
                                   max=1e-4)
    '''))
    result = subprocess.run([base_install / "bin" / "python", "-m", "pytest", "-q",
                             "-p", "no:cacheprovider", tmp_path / "test_images.py"],
                            capture_output=True, text=True, cwd=tmp_path)
    assert result.returncode == 0, result.stdout[-2000:] + result.stderr[-2000:]
    assert "2 passed" in result.stdout


def test_every_optional_package_of_the_extras_is_mapped_to_its_extra():
    from translucent.extras import EXTRAS, missing_extra

    try:
        import tomllib
    except ModuleNotFoundError:  # Python 3.10
        import tomli as tomllib
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    extras = project["optional-dependencies"]
    names = {"pywavelets": "pywt", "dask[distributed]": "dask",
             "karellen-llvm-core": None}
    for extra in ("render", "fast", "fit", "distributed"):
        for requirement in extras[extra]:
            package = requirement.split(";")[0].split(">=")[0].strip().lower()
            if package.startswith("translucent["):
                continue
            module = names.get(package, package)
            if module is not None:
                assert module in EXTRAS, package
    base = " ".join(project["dependencies"]).lower()
    assert not any(name in base for name in ("mitsuba", "drjit", "numba", "dask", "emcee"))
    error = ModuleNotFoundError("No module named 'mitsuba'", name="mitsuba")
    assert missing_extra(RuntimeError("not an import")) is None
    assert missing_extra(ModuleNotFoundError("No module named 'x'", name="x")) is None
    try:
        raise RuntimeError("while loading a scene") from error
    except RuntimeError as wrapped:
        found = missing_extra(wrapped)
    assert found is not None and found.value == "render" and "translucent[render]" in str(found)
