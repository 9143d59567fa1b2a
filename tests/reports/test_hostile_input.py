"""Hostile and bad input across every command: exit 2, a message naming what is wrong, no
traceback, and no file left behind.

Each case is one kind of bad input. ``files`` are made in a fresh folder before the
command runs; afterwards that folder holds exactly those files again (nothing written,
nothing half-written, no temporary left), and standard error names the words of the case
(the file, the field, the value).
"""

import json
import os

import numpy as np
import pytest
from translucent.image import Image
from translucent.reports.cli import main
from translucent.scenes import load_scene

#: At least this many kinds are checked (issue "Nothing lost, nothing trusted blindly").
LEAST_KINDS = 50


def _sphere_text() -> str:
    """The built-in sphere's scene file."""
    from pathlib import Path

    return Path(load_scene("sphere").source).read_text(encoding="utf-8")


def _exr(size=(8, 8), value=0.5, variance=None, nan=False) -> bytes:
    """The bytes of a small EXR (written through a temporary file)."""
    import tempfile

    rgb = np.full(size + (3,), value, dtype=np.float32)
    with tempfile.TemporaryDirectory() as folder:
        path = os.path.join(folder, "image.exr")
        if nan:  # the suite never writes one: OpenEXR directly, as another renderer would
            import OpenEXR

            rgb[0, 0, 0] = np.nan
            with OpenEXR.File({"compression": OpenEXR.ZIP_COMPRESSION,
                               "type": OpenEXR.scanlineimage}, {"RGB": rgb}) as exr:
                exr.write(path)
        else:
            Image(rgb, None if variance is None else np.full_like(rgb, variance)).write(path)
        with open(path, "rb") as handle:
            return handle.read()


SPHERE = _sphere_text()
GOOD_EXR = _exr()
CAPTURE_SIDECAR = {"format": "translucent-capture", "version": 1}


class CaptureFile(str):
    """A file of a small synthetic capture (made once by the ``capture`` fixture)."""


#: A valid 32 x 32 capture: its sidecar and image.
CAPTURE = {"c.json": CaptureFile("small.json"), "small.exr": CaptureFile("small.exr")}

#: kind -> (arguments, files {name: text or bytes}, words stderr must hold)
CASES = {
    # ----------------------------------------------------------------- scenes
    "unknown built-in scene": (["render", "no_such_scene"], {}, ["no_such_scene"]),
    "missing scene file": (["render", "{d}/missing.toml"], {}, ["missing.toml"]),
    "scene file not UTF-8": (["render", "{d}/latin.toml"], {"latin.toml": b"name = '\xe9'\n"},
                             ["latin.toml", "utf-8"]),
    "scene file not TOML": (["render", "{d}/bad.toml"], {"bad.toml": "[scene\nname = 1\n"},
                            ["bad.toml"]),
    "boundary index below 1": (["render", "{d}/s.toml"],
                            {"s.toml": SPHERE.replace('name = "Marble", eta = 1.0',
                                                      'name = "Marble", eta = -1.0')},
                            ["s.toml", "eta"]),
    "camera of zero width": (["render", "{d}/s.toml"],
                             {"s.toml": SPHERE.replace("width = 96", "width = 0")},
                             ["s.toml", "width"]),
    "camera too large for the memory": (["render", "{d}/s.toml", "--spp", "1"],
                                        {"s.toml": SPHERE.replace("width = 96", "width = 16384")
                                         .replace("height = 96", "height = 16384")},
                                        ["s.toml", "16384 x 16384", "of memory"]),
    "camera beyond the largest size": (["render", "{d}/s.toml"],
                                       {"s.toml": SPHERE.replace("width = 96", "width = 70000")},
                                       ["s.toml", "camera.width", "70000"]),
    "unknown light type": (["render", "{d}/s.toml"],
                           {"s.toml": SPHERE.replace('type = "point"', 'type = "laser"')},
                           ["s.toml", "laser"]),
    "non-finite light position": (["render", "{d}/s.toml"],
                                  {"s.toml": SPHERE.replace("position = [3.0, 4.0, 4.0]",
                                                            "position = [nan, 4.0, 4.0]")},
                                  ["s.toml", "position"]),
    "unknown measured medium": (["render", "{d}/s.toml"],
                                {"s.toml": SPHERE.replace('name = "Marble"', 'name = "Cheese"')},
                                ["s.toml", "Cheese"]),
    # ----------------------------------------------------------------- render options
    "zero spp": (["render", "sphere", "--spp", "0", "--out", "{d}/o.exr"], {}, ["spp", "0"]),
    "negative passes": (["render", "sphere", "--passes", "-2", "--out", "{d}/o.exr"], {},
                        ["passes", "-2"]),
    "too many samples for 32 bits": (["render", "sphere", "--spp", "500000", "--out",
                                      "{d}/o.exr"], {}, ["spp", "500000", "32 bits"]),
    "target RSE of zero": (["render", "sphere", "--target-rse", "0", "--out", "{d}/o.exr"], {},
                           ["target", "0"]),
    "target RSE above one": (["render", "sphere", "--target-rse", "1.5", "--out", "{d}/o.exr"],
                             {}, ["target", "1.5"]),
    "negative budget": (["render", "sphere", "--target-rse", "0.1", "--budget", "-1", "--out",
                         "{d}/o.exr"], {}, ["budget", "-1"]),
    "unknown integrator": (["render", "sphere", "--integrator", "bdpt"], {}, ["integrator",
                                                                             "bdpt"]),
    "render output into /proc": (["render", "sphere", "--spp", "1", "--passes", "1", "--out",
                                  "/proc/translucent.exr"], {}, ["/proc/translucent.exr"]),
    "render output that is a folder": (["render", "sphere", "--out", "{d}/folder"],
                                       {"folder/keep.txt": "x"}, ["folder"]),
    # ----------------------------------------------------------------- compare
    "compare: missing test image": (["compare", "{d}/none.exr", "{d}/ref.exr"],
                                    {"ref.exr": GOOD_EXR}, ["none.exr"]),
    "compare: text as EXR": (["compare", "{d}/a.exr", "{d}/ref.exr"],
                             {"a.exr": "not an image", "ref.exr": GOOD_EXR}, ["a.exr"]),
    "compare: truncated EXR": (["compare", "{d}/a.exr", "{d}/ref.exr"],
                               {"a.exr": GOOD_EXR[:60], "ref.exr": GOOD_EXR}, ["a.exr"]),
    "compare: sizes differ": (["compare", "{d}/a.exr", "{d}/ref.exr"],
                              {"a.exr": _exr((8, 9)), "ref.exr": GOOD_EXR}, ["8", "9"]),
    "compare: NaN in the reference": (["compare", "{d}/a.exr", "{d}/ref.exr"],
                                      {"a.exr": GOOD_EXR, "ref.exr": _exr(nan=True)},
                                      ["ref.exr", "NaN"]),
    "compare: maps into /proc": (["compare", "{d}/a.exr", "{d}/ref.exr", "--maps",
                                  "/proc/maps_here"],
                                 {"a.exr": GOOD_EXR, "ref.exr": GOOD_EXR}, ["/proc/maps_here"]),
    # ----------------------------------------------------------------- approx
    "approx: unknown method": (["approx", "phong", "sphere"], {}, ["phong"]),
    "approx: samples not parts x 4^n": (["approx", "prt", "sphere", "--samples", "1000",
                                         "--out", "{d}/o.exr"], {}, ["samples", "1000"]),
    "approx: zero form-factor rays": (["approx", "radiosity", "sphere", "--rays", "0",
                                       "--out", "{d}/o.exr"], {}, ["rays_per_patch", "0"]),
    "approx: zero mipmap levels": (["approx", "splatting", "heterogeneous", "--levels", "0",
                                    "--out", "{d}/o.exr"], {}, ["levels", "0"]),
    "approx: gamma out of range": (["approx", "brdf_pca", "glossy", "--object", "sphere",
                                    "--gamma", "1e9", "--out", "{d}/o.exr"], {},
                                   ["gamma", "1000000000.0"]),
    "approx: output not EXR": (["approx", "prt", "sphere", "--out", "{d}/o.png"], {},
                               ["--out", "o.png"]),
    "approx: sigma_a without sigma_s'": (["approx", "prt", "sphere", "--sigma-a", "1", "1", "1",
                                          "--out", "{d}/o.exr"], {}, ["sigma"]),
    "approx: method refuses the scene": (["approx", "brdf_pca", "sphere", "--out",
                                          "{d}/o.exr"], {}, ["sphere"]),
    # ----------------------------------------------------------------- capture
    "capture: unknown material": (["capture", "cheese", "--out", "{d}/c.json"], {},
                                  ["cheese"]),
    "capture: too small": (["capture", "skin1", "--size", "8", "--out", "{d}/c.json"], {},
                           ["--size", "8"]),
    "capture: NaN photons": (["capture", "skin1", "--photons", "nan", "--out", "{d}/c.json"], {},
                             ["--photons", "nan"]),
    "capture: photons beyond the memory": (["capture", "skin1", "--photons", "1e15", "--out",
                                            "{d}/c.json"], {}, ["--photons", "of memory"]),
    "capture: size beyond the memory": (["capture", "skin1", "--size", "100000", "--out",
                                         "{d}/c.json"], {}, ["--size", "100000", "of memory"]),
    "capture: zero pixel size": (["capture", "skin1", "--pixel-size", "0", "--out",
                                  "{d}/c.json"], {}, ["--pixel-size", "0"]),
    "capture: top-hat beam from the walk": (["capture", "skin1", "--beam-profile", "top_hat",
                                             "--out", "{d}/c.json"], {}, ["--beam-profile"]),
    "capture: sidecar over its image": (["capture", "skin1", "--out", "{d}/c.exr"], {},
                                        ["--out", "c.exr"]),
    # ----------------------------------------------------------------- fit
    "fit: missing capture": (["fit", "{d}/none.json"], {}, ["none.json"]),
    "fit: sidecar not JSON": (["fit", "{d}/c.json", "--out", "{d}/fit"],
                              {"c.json": "{not json"}, ["c.json"]),
    "fit: sidecar of another format": (["fit", "{d}/c.json", "--out", "{d}/fit"],
                                       {"c.json": json.dumps({"format": "png"})}, ["c.json"]),
    "fit: incomplete sidecar": (["fit", "{d}/c.json", "--out", "{d}/fit"],
                                {"c.json": json.dumps(CAPTURE_SIDECAR)}, ["c.json"]),
    "fit: zero segments with both models": (["fit", "{d}/c.json", "--model", "both",
                                             "--segments", "0", "--out", "{d}/fit"], CAPTURE,
                                            ["segments", "0"]),
    "fit: one walker": (["fit", "{d}/c.json", "--walkers", "1", "--out", "{d}/fit"], CAPTURE,
                        ["walkers", "1"]),
    "fit: image missing beside the sidecar": (["fit", "{d}/c.json", "--out", "{d}/fit"],
                                              {"c.json": CAPTURE["c.json"]}, ["small.exr"]),
    "fit: image of another size": (["fit", "{d}/c.json", "--out", "{d}/fit"],
                                   {"c.json": CAPTURE["c.json"], "small.exr": _exr((8, 8))},
                                   ["c.json", "incident_px", "inside the image"]),
    "fit: negative r_min": (["fit", "{d}/c.json", "--r-min", "-1", "--out", "{d}/fit"],
                           CAPTURE, ["r_min", "-1"]),
    # ----------------------------------------------------------------- bench, stress, report
    "bench: samples list with a word": (["bench", "prt", "--samples", "1024,abc"], {},
                                        ["--samples", "abc"]),
    "bench: zero max spp": (["bench", "tradeoff", "--max-spp", "0"], {}, ["--max-spp", "0"]),
    "bench: fitting capture too small": (["bench", "fitting", "--size", "8"], {},
                                         ["--size", "8"]),
    "stress: JSON into /proc": (["stress", "--only", "total diffuse", "--json",
                                 "/proc/stress.json"], {}, ["/proc/stress.json"]),
    "report: unknown method": (["report", "--methods", "phong", "--out", "{d}/r"], {},
                               ["phong"]),
    "report: output into /proc": (["report", "--out", "/proc/report_here"], {},
                                  ["/proc/report_here"]),
    "report: images folder missing": (["report", "--images", "{d}/none", "--out", "{d}/r"], {},
                                      ["none"]),
    # ----------------------------------------------------------------- export, references
    "export: unknown format": (["export", "sphere", "--format", "pbrt", "--out", "{d}/e"], {},
                               ["--format", "pbrt"]),
    "export: zero spp": (["export", "sphere", "--spp", "0", "--out", "{d}/e"], {},
                         ["spp", "0"]),
    "references: unknown scene": (["references", "render", "no_such_scene"], {},
                                  ["no_such_scene"]),
    "capture-import: missing photo": (["capture-import", "{d}/photo.tif", "--pixel-size-mm",
                                       "0.1", "--out", "{d}/c.json"], {}, ["photo.tif"]),
    "capture-import: unsupported photo format": (["capture-import", "{d}/photo.png",
                                                  "--pixel-size-mm", "0.1", "--out",
                                                  "{d}/c.json"], {"photo.png": b"\x89PNG"},
                                                 ["photo.png", ".png"]),
}


@pytest.fixture(scope="module")
def capture(tmp_path_factory):
    """The bytes of a 32 x 32 dipole capture: sidecar and image."""
    folder = tmp_path_factory.mktemp("capture")
    assert main(["capture", "skin1", "--generator", "dipole", "--size", "32", "--out",
                 str(folder / "small.json"), "--quiet"]) == 0
    return {name: (folder / name).read_bytes() for name in ("small.json", "small.exr")}


def _tree(folder) -> dict:
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*"))
            if p.is_file()}


def test_the_module_checks_at_least_fifty_kinds():
    assert len(CASES) >= LEAST_KINDS


@pytest.mark.parametrize("kind", sorted(CASES))
def test_bad_input_is_refused_cleanly(kind, tmp_path, capsys, monkeypatch, capture):
    from translucent import resources

    # the memory cases do not depend on the machine the tests run on
    monkeypatch.setattr(resources, "available_memory", lambda: 8 * 2**30)
    arguments, files, words = CASES[kind]
    folder = tmp_path / "work"
    folder.mkdir()
    for name, content in files.items():
        if isinstance(content, CaptureFile):
            content = capture[str(content)]
        path = folder / name
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_bytes(content if isinstance(content, bytes) else content.encode("utf-8"))
    before = _tree(folder)
    monkeypatch.chdir(folder)
    code = main([part.replace("{d}", str(folder)) for part in arguments])
    out, err = capsys.readouterr()
    assert code == 2, (out, err)
    assert "Traceback" not in err + out
    for word in words:
        assert word.replace("{d}", str(folder)) in err, (word, err)
    assert _tree(folder) == before, "files were written or left behind"
