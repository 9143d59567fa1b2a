"""Hostile and bad input across every command: exit 2, a message naming what is wrong, no
traceback, and no file left behind.

Each case is one kind of bad input (:mod:`hostile` runs it). ``files`` are made in a fresh
folder before the command runs; afterwards that folder holds exactly those files again
(nothing written, nothing half-written, no temporary left), and standard error names the
words of the case (the file, the field, the value). The kinds that would destroy an input
are in ``test_hostile_outputs.py``, those of the cache in ``test_hostile_cache.py``.
"""

import contextlib
import json
import os
import subprocess
import sys

import numpy as np
import pytest
from hostile import (
    SPHERE,
    TINY_SPHERE,
    CaptureFile,
    Made,
    declaring,
    exr_bytes,
    nested_json,
    npz_declaring,
    run_case,
    sparse,
    sphere_text,
    written,
)
from translucent.reports.cli import main

#: At least this many kinds are checked across the hostile-input modules (issue "Never
#: destroy an input, never serve what was not made for the key").
LEAST_KINDS = 90


def _exr(size=(8, 8), value=0.5, variance=None, nan=False) -> bytes:
    """The bytes of a small EXR; with ``nan`` one pixel is NaN, as another renderer writes."""
    if not nan:
        return exr_bytes(size, value, variance)
    rgb = np.full(size + (3,), value, dtype=np.float32)
    rgb[0, 0, 0] = np.nan
    return exr_bytes(channels={"RGB": rgb})


GOOD_EXR = _exr()
CAPTURE_SIDECAR = {"format": "translucent-capture", "version": 1}

#: A valid 32 x 32 capture: its sidecar and image.
CAPTURE = {"c.json": CaptureFile("small.json"), "small.exr": CaptureFile("small.exr")}

#: The mesh table of the sphere's object, replaced by the cases that give a mesh file.
SPHERE_MESH = ('mesh = { type = "icosphere", subdivisions = 4, radius = 1.0, '
               'center = [0.0, 0.0, 0.0] }')
#: The sphere's material, replaced by the SubEdit cases.
SPHERE_MATERIAL = 'material = { type = "measured", name = "Marble", eta = 1.0 }'
#: The sphere's scene name.
SPHERE_NAME = 'name = "sphere"\ndescription'
#: 400 digits: an integer no float64 holds.
HUGE = "9" * 400

#: Arguments that keep a render that should have been refused short.
ONE_SAMPLE = ["--spp", "1", "--passes", "1", "--no-cache"]


def _meshed(name: str) -> str:
    """The sphere's scene at 16 x 16 pixels with its object's mesh read from ``name``."""
    return sphere_text(**{SPHERE_MESH: f'mesh = {{ file = "{name}" }}', "width = 96":
                          "width = 16", "height = 96": "height = 16"})


#: A named pipe that nothing writes: a command that opened it would wait for ever.
FIFO = Made(os.mkfifo)


def _device(path):
    """Make a character device node of the test's own (reads as empty), never the machine's."""
    import stat

    try:
        os.mknod(path, stat.S_IFCHR | 0o600, os.makedev(1, 3))
    except PermissionError:
        pytest.skip("making a device node needs root")


#: A device where a file is expected.
DEVICE = Made(_device)

#: A sidecar whose beam is measured in ``beam.exr``.
MEASURED_BEAM_SIDECAR = {"image": "small.exr", "pixel_size_mm": 0.25, "incident_px": [16, 16],
                         "side": "reflection", "black_level": 256.0,
                         "saturation_level": 65535.0, "beam_profile": "measured",
                         "beam_image": "beam.exr"}

#: An ASCII PLY whose header declares ten million faces over the two it holds.
PLY_OF_TWO_FACES = ("ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\n"
                    "property float y\nproperty float z\nelement face 10000000\n"
                    "property list uchar int vertex_indices\nend_header\n"
                    "0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n3 0 2 1\n")

#: An OFF whose header line counts ten million faces over the two it holds.
OFF_OF_TWO_FACES = "OFF\n3 10000000 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n3 0 2 1\n"


def _subsampled() -> bytes:
    """An EXR whose G channel has one sample per 2 x 2 pixels."""
    import OpenEXR

    full = np.full((16, 16), 0.5, np.float32)
    # OpenEXR's writer keeps every other sample of the plane given for a subsampled channel
    return exr_bytes(channels={"R": OpenEXR.Channel(full), "B": OpenEXR.Channel(full),
                               "G": OpenEXR.Channel(full, 2, 2)})


def _variance_planes(**planes) -> bytes:
    """A 16 x 16 EXR with R, G, B of 0.5 and the given variance planes."""
    rgb = {c: np.full((16, 16), 0.5, np.float32) for c in "RGB"}
    return exr_bytes(channels={**rgb, **{name.replace("_", "."): np.full((16, 16), value,
                                                                         np.float32)
                                         for name, value in planes.items()}})


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
    # ----------------------------------------------------------------- nested, huge, long
    "scene nested 5000 deep": (["render", "{d}/s.toml"],
                               {"s.toml": SPHERE + f"\n[extra]\nx = {nested_json(5000)}\n"},
                               ["s.toml", "nested"]),
    "scene integer of 400 digits": (["render", "{d}/s.toml"],
                                    {"s.toml": sphere_text(**{"intensity = 100.0":
                                                              f"intensity = {HUGE}"})},
                                    ["s.toml", "lights[0].intensity", "400 digits"]),
    "mesh count of 400 digits": (["render", "{d}/s.toml"],
                                 {"s.toml": sphere_text(**{"subdivisions = 4":
                                                           f"subdivisions = {HUGE}"})},
                                 ["s.toml", "subdivisions"]),
    "camera width of 400 digits": (["render", "{d}/s.toml"],
                                   {"s.toml": sphere_text(**{"width = 96": f"width = {HUGE}"})},
                                   ["s.toml", "camera.width"]),
    "light position of 400 digits": (["render", "{d}/s.toml"],
                                     {"s.toml": sphere_text(**{"[3.0, 4.0, 4.0]":
                                                               f"[{HUGE}, 4.0, 4.0]"})},
                                     ["s.toml", "position"]),
    "scene path of 5000 characters": (["render", "{d}/" + "s" * 5000 + ".toml"], {},
                                      ["scene", "too long"]),
    "output path of 5000 characters": (["render", "sphere", "--out",
                                        "{d}/" + "o" * 5000 + ".exr"], {},
                                       ["--out", "too long"]),
    "mesh file name of 5000 characters": (["render", "{d}/s.toml"],
                                          {"s.toml": sphere_text(**{SPHERE_MESH: 'mesh = { file '
                                                                    f'= "{"m" * 5000}.obj" }}'})},
                                          ["s.toml", "file", "too long"]),
    "scene name of 5000 characters": (["render", "{d}/s.toml", "--spp", "0"],
                                      {"s.toml": sphere_text(**{
                                          SPHERE_NAME: f'name = "{"n" * 5000}"\ndescription'})},
                                      ["spp = 0"]),
    "NUL in a mesh file name": (["render", "{d}/s.toml"],
                                {"s.toml": sphere_text(**{SPHERE_MESH:
                                                          'mesh = { file = "a\\u0000.obj" }'})},
                                ["s.toml", "null byte"]),
    "camera fov of the wrong type": (["render", "{d}/s.toml"],
                                     {"s.toml": sphere_text(**{"fov = 30.0": "fov = [30, 40]"})},
                                     ["s.toml", "camera.fov", "[30, 40]"]),
    "scene that is a folder": (["render", "{d}/f.toml"], {"f.toml/keep": "x"},
                               ["f.toml", "is a folder"]),
    "mesh file that is a folder": (["render", "{d}/s.toml"],
                                   {"s.toml": sphere_text(**{SPHERE_MESH: 'mesh = { file = '
                                                             '"m.obj" }'}), "m.obj/keep": "x"},
                                   ["m.obj", "is a folder"]),
    "unreadable text STL": (["render", "{d}/s.toml"],
                            {"s.toml": sphere_text(**{SPHERE_MESH: 'mesh = { file = "m.stl" }'}),
                             "m.stl": b"solid x\n facet \xff\xfe\xfd garbage\n"},
                            ["m.stl", "not a readable mesh", "convert it"]),
    "sparse mesh of a gigabyte": (["render", "{d}/s.toml"],
                                  {"s.toml": sphere_text(**{SPHERE_MESH: 'mesh = { file = '
                                                            '"m.obj" }'}), "m.obj": sparse(2**30)},
                                  ["m.obj", "holes"]),
    "mesh file beyond the memory": (["render", "{d}/s.toml"],
                                    {"s.toml": sphere_text(**{SPHERE_MESH: 'mesh = { file = '
                                                              '"m.obj" }'}),
                                     "m.obj": written(2**22)}, ["m.obj", "of memory"],
                                    {"memory": 2**26}),
    "SubEdit texture of 74 GiB": (["render", "{d}/s.toml"],
                                  {"s.toml": sphere_text(**{SPHERE_MATERIAL: 'material = { type = '
                                                            '"subedit", builtin = "checker", '
                                                            'resolution = 7000 }'})},
                                  ["s.toml", "resolution", "7000", "of memory"]),
    "SubEdit file declaring 74 GiB": (["render", "{d}/s.toml"],
                                      {"s.toml": sphere_text(**{SPHERE_MATERIAL: 'material = { '
                                                                'type = "subedit", file = '
                                                                '"t.npz" }'}),
                                       "t.npz": npz_declaring((7000, 7000, 65, 3))},
                                      ["s.toml", "t.npz", "of memory"]),
    "SubEdit r_s of 1e308": (["render", "{d}/s.toml"],
                             {"s.toml": sphere_text(**{SPHERE_MATERIAL: 'material = { type = '
                                                       '"subedit", measured = "Marble", r_s = '
                                                       '1e308 }'})}, ["s.toml", "r_s", "1e+308"]),
    # ----------------------------------------------------------------- counts and settings
    "passes beyond any render": (["render", "sphere", "--passes", "99999999999999999999",
                                  "--out", "{d}/o.exr"], {}, ["passes", "99999999999999999999"]),
    "seed beyond 64 bits": (["render", "sphere", "--seed", str(2**70), "--out", "{d}/o.exr"],
                            {}, ["seed", str(2**70)]),
    "capture: negative seed": (["capture", "skin1", "--seed", "-1", "--out", "{d}/c.json"], {},
                               ["--seed", "-1"]),
    "export: spp beyond 32 bits": (["export", "sphere", "--spp", "99999999999999999999",
                                    "--out", "{d}/e"], {}, ["spp", "99999999999999999999"]),
    "TRANSLUCENT_OPTIONS asks for help": (["scenes"], {}, ["TRANSLUCENT_OPTIONS", "--help"],
                                          {"env": {"TRANSLUCENT_OPTIONS": "--help"}}),
    "cache budget not a number": (["render", "{d}/s.toml", "--out", "{d}/o.exr"],
                                  {"s.toml": TINY_SPHERE}, ["TRANSLUCENT_CACHE_MAX_BYTES", "abc"],
                                  # the cache inside the folder: an entry stored by a render
                                  # that ran before the refusal would show
                                  {"env": {"TRANSLUCENT_CACHE_MAX_BYTES": "abc",
                                           "TRANSLUCENT_CACHE": "{d}/cache"}}),
    "cache folder of an unknown user": (["scenes"], {},
                                        ["TRANSLUCENT_CACHE", "~no_such_user_here"],
                                        {"env": {"TRANSLUCENT_CACHE": "~no_such_user_here/c"}}),
    "report: output of an unknown user": (["report", "--out", "~no_such_user_here/r"], {},
                                          ["--out", "~no_such_user_here"]),
    # ----------------------------------------------------------------- EXR files
    "compare: subsampled channel": (["compare", "{d}/ref.exr", "{d}/a.exr"],
                                    {"a.exr": _subsampled(), "ref.exr": exr_bytes()},
                                    ["a.exr", "channel G", "subsampled"]),
    "compare: metadata a JSON list": (["compare", "{d}/ref.exr", "{d}/a.exr"],
                                      {"a.exr": exr_bytes(header={"translucent:metadata":
                                                                  "[1, 2]"}),
                                       "ref.exr": exr_bytes()},
                                      ["a.exr", "translucent:metadata", "JSON object"]),
    "compare: metadata nested 100000 deep": (["compare", "{d}/ref.exr", "{d}/a.exr"],
                                             {"a.exr": exr_bytes(header={
                                                 "translucent:metadata": nested_json(100000)}),
                                              "ref.exr": exr_bytes()},
                                             ["a.exr", "translucent:metadata", "nested"]),
    "compare: 16384 x 16384 declared": (["compare", "{d}/ref.exr", "{d}/a.exr"],
                                        {"a.exr": declaring(exr_bytes(), 16384, 16384),
                                         "ref.exr": exr_bytes()},
                                        ["a.exr", "16384 x 16384", "of memory"]),
    "compare: one variance channel of three": (["compare", "{d}/ref.exr", "{d}/a.exr"],
                                               {"ref.exr": _variance_planes(variance_R=0.1),
                                                "a.exr": exr_bytes()},
                                               ["ref.exr", "variance.R"]),
    "compare: NaN variance": (["compare", "{d}/ref.exr", "{d}/a.exr"],
                              {"ref.exr": _variance_planes(variance_R=np.nan,
                                                           variance_G=0.1, variance_B=0.1),
                               "a.exr": exr_bytes()}, ["ref.exr", "NaN", "variance"]),
    "compare: negative variance": (["compare", "{d}/ref.exr", "{d}/a.exr"],
                                   {"ref.exr": _variance_planes(variance_R=-1.0,
                                                                variance_G=0.1, variance_B=0.1),
                                    "a.exr": exr_bytes()}, ["ref.exr", "negative"]),
    "compare: a folder as the reference": (["compare", "{d}/ref.exr", "{d}/a.exr"],
                                           {"ref.exr/keep": "x", "a.exr": exr_bytes()},
                                           ["ref.exr", "is a folder"]),
    # ----------------------------------------------------------------- fit and captures
    "fit: sidecar nested 100000 deep": (["fit", "{d}/c.json", "--out", "{d}/fit"],
                                        {"c.json": nested_json(100000)}, ["c.json", "nested"]),
    "fit: sidecar a JSON list": (["fit", "{d}/c.json", "--out", "{d}/fit"],
                                 {"c.json": "[1, 2]"}, ["c.json", "JSON object"]),
    "fit: integer of 400 digits in the sidecar": (["fit", "{d}/c.json", "--out", "{d}/fit"],
                                                  {"c.json": json.dumps(
                                                      {**CAPTURE_SIDECAR, "image": "small.exr",
                                                       "pixel_size_mm": "HUGE",
                                                       "incident_px": [1, 2]}).replace(
                                                      '"HUGE"', HUGE)},
                                                  ["c.json", "pixel_size_mm"]),
    "fit: image that is a folder": (["fit", "{d}/c.json", "--out", "{d}/fit"],
                                    {"c.json": CAPTURE["c.json"], "small.exr/keep": "x"},
                                    ["small.exr", "is a folder"]),
    "fit: one walker, said as given": (["fit", "{d}/c.json", "--walkers", "1", "--out",
                                        "{d}/fit"], CAPTURE, ["walkers = 1"]),
    "fit: negative step budget": (["fit", "{d}/c.json", "--max-steps", "-1", "--out",
                                   "{d}/fit"], CAPTURE, ["max_steps", "-1"]),
    "fit: walkers beyond the memory": (["fit", "{d}/c.json", "--walkers", "99999999999999999999",
                                        "--out", "{d}/fit"], CAPTURE,
                                       ["walkers", "99999999999999999999", "of memory"]),
    "fit: segments beyond any profile": (["fit", "{d}/c.json", "--model", "subedit",
                                          "--segments", "99999999999999999999", "--out",
                                          "{d}/fit"], CAPTURE, ["segments", "1024"]),
    "capture-import: photo that is a folder": (["capture-import", "{d}/photo.tif",
                                                "--pixel-size-mm", "0.1", "--out",
                                                "{d}/c.json"], {"photo.tif/keep": "x"},
                                               ["photo.tif", "is a folder"]),
    # ----------------------------------------------------------------- meshes that lie
    "ASCII PLY declaring ten million faces": (["render", "{d}/s.toml", *ONE_SAMPLE],
                                              {"s.toml": _meshed("m.ply"),
                                               "m.ply": PLY_OF_TWO_FACES},
                                              ["m.ply", "element face", "10000000",
                                               "holds only 2 face lines"]),
    "OFF declaring ten million faces": (["render", "{d}/s.toml", *ONE_SAMPLE],
                                        {"s.toml": _meshed("m.off"), "m.off": OFF_OF_TWO_FACES},
                                        ["m.off", "face count (line 2)", "10000000",
                                         "holds only 2 face lines"]),
    "OBJ coordinate beyond float32": (["render", "{d}/s.toml", *ONE_SAMPLE],
                                      {"s.toml": _meshed("m.obj"),
                                       "m.obj": "v 0 0 0\nv 1 0 0\nv 0 1e39 0\nf 1 2 3\n"},
                                      ["m.obj", "line 3 = 1e+39", "float32"]),
    "icosphere beyond float32": (["render", "{d}/s.toml", *ONE_SAMPLE],
                                 {"s.toml": TINY_SPHERE.replace("radius = 1.0", "radius = 1e39")},
                                 ["s.toml", "objects[0].mesh", "float32"]),
    # ----------------------------------------------------------------- what is not a file
    **{f"{command}: {what} a FIFO": (arguments, {**files, name: FIFO}, [name, "FIFO"])
       for command, what, arguments, files, name in (
        ("render", "scene file", ["render", "{d}/s.toml"], {}, "s.toml"),
        ("render", "mesh file", ["render", "{d}/s.toml"], {"s.toml": _meshed("m.obj")},
         "m.obj"),
        ("render", "SubEdit file", ["render", "{d}/s.toml"],
         {"s.toml": sphere_text(**{SPHERE_MATERIAL: 'material = { type = "subedit", file = '
                                                    '"t.npz" }'})}, "t.npz"),
        ("export", "scene file", ["export", "{d}/s.toml", "--out", "{d}/e"], {}, "s.toml"),
        ("report", "scene file", ["report", "{d}/s.toml", "--out", "{d}/r"], {}, "s.toml"),
        ("report", "renderer's image", ["report", "sphere", "--images", "{d}/im", "--out",
                                        "{d}/r"], {}, "im/other/sphere.exr"),
        ("capture", "material file", ["capture", "{d}/m.toml", "--out", "{d}/c.json"], {},
         "m.toml"),
        ("fit", "sidecar", ["fit", "{d}/c.json", "--out", "{d}/fit"], {}, "c.json"),
        ("fit", "image", ["fit", "{d}/c.json", "--out", "{d}/fit"],
         {"c.json": CAPTURE["c.json"]}, "small.exr"),
        ("fit", "beam image", ["fit", "{d}/c.json", "--out", "{d}/fit"],
         {"c.json": json.dumps(MEASURED_BEAM_SIDECAR), "small.exr": CAPTURE["small.exr"]},
         "beam.exr"),
        ("capture-import", "photo", ["capture-import", "{d}/photo.exr", "--pixel-size-mm", "0.1",
                                     "--out", "{d}/c.json"], {}, "photo.exr"),
        ("capture-import", "dark frame", ["capture-import", "{d}/photo.exr", "--dark",
                                          "{d}/dark.exr", "--pixel-size-mm", "0.1", "--out",
                                          "{d}/c.json"], {"photo.exr": GOOD_EXR}, "dark.exr"),
        ("capture-import", "beam image", ["capture-import", "{d}/photo.exr", "--beam-image",
                                          "{d}/beam.exr", "--pixel-size-mm", "0.1", "--out",
                                          "{d}/c.json"], {"photo.exr": GOOD_EXR}, "beam.exr"),
        ("report", "baseline", ["report", "sphere", "--baseline", "{d}/b.json", "--out",
                                "{d}/r"], {}, "b.json"),
        ("compare", "reference", ["compare", "{d}/ref.exr", "{d}/a.exr"], {"a.exr": GOOD_EXR},
         "ref.exr"),
        ("compare", "test image", ["compare", "{d}/ref.exr", "{d}/a.exr"],
         {"ref.exr": GOOD_EXR}, "a.exr"),
    )},
    "render: scene file a device": (["render", "{d}/s.toml"], {"s.toml": DEVICE},
                                    ["s.toml", "device"]),
    "fit: image a device": (["fit", "{d}/c.json", "--out", "{d}/fit"],
                            {"c.json": CAPTURE["c.json"], "small.exr": DEVICE},
                            ["small.exr", "device"]),
    "report: renderer's image a folder": (["report", "sphere", "--images", "{d}/im", "--out",
                                           "{d}/r"], {"im/other/sphere.exr/keep": "x"},
                                          ["im/other/sphere.exr", "is a folder"]),
    "report: renderer's image a link loop": (["report", "sphere", "--images", "{d}/im",
                                              "--out", "{d}/r"],
                                             {"im/other/sphere.exr": Made(
                                                 lambda path: os.symlink(path.name, path))},
                                             ["im/other/sphere.exr", "symbolic links"]),
}


@pytest.fixture(scope="module")
def capture(tmp_path_factory):
    """The bytes of a 32 x 32 dipole capture: sidecar and image."""
    folder = tmp_path_factory.mktemp("capture")
    assert main(["capture", "skin1", "--generator", "dipole", "--size", "32", "--out",
                 str(folder / "small.json"), "--quiet"]) == 0
    return {name: (folder / name).read_bytes() for name in ("small.json", "small.exr")}


def test_the_modules_check_at_least_ninety_kinds():
    import test_hostile_cache
    import test_hostile_outputs

    kinds = len(CASES) + len(test_hostile_outputs.CASES) + len(test_hostile_cache.KINDS)
    assert kinds >= LEAST_KINDS, kinds


#: What :func:`_fifo_guard` runs: ``after`` seconds in, it opens and closes for writing
#: every FIFO of the folder that a reader holds open, printing its name.
_UNBLOCK = """
import os, stat, sys, time
folder, after = sys.argv[1], float(sys.argv[2])
time.sleep(after)
fifos = [os.path.join(top, name) for top, folders, names in os.walk(folder)
         for name in names if stat.S_ISFIFO(os.lstat(os.path.join(top, name)).st_mode)]
while True:
    for fifo in fifos:
        try:
            os.close(os.open(fifo, os.O_WRONLY | os.O_NONBLOCK))
        except OSError:
            continue
        print(os.path.basename(fifo), flush=True)
    time.sleep(0.05)
"""


@contextlib.contextmanager
def _fifo_guard(folder, after: float = 2.0):
    """Yield the names of the FIFOs of ``folder`` a command opened (filled on exit).

    A command that waits on a FIFO is let go after ``after`` seconds (it reads an empty
    file), so it costs seconds, never the suite. The guard is another process: a reader
    blocked in an extension that holds the interpreter's lock stops every thread of this
    one.
    """
    guard = subprocess.Popen([sys.executable, "-I", "-S", "-c", _UNBLOCK, str(folder),
                              str(after)], stdout=subprocess.PIPE, text=True)
    opened: list[str] = []
    try:
        yield opened
    finally:
        guard.kill()
        opened += guard.communicate()[0].split()


@pytest.mark.parametrize("kind", sorted(CASES))
def test_bad_input_is_refused_cleanly(kind, tmp_path, capsys, monkeypatch, capture):
    folder = tmp_path / "work"
    folder.mkdir()
    fifo = any(content is FIFO for content in CASES[kind][1].values())
    with _fifo_guard(folder) if fifo else contextlib.nullcontext([]) as opened:
        run_case(CASES[kind], folder, monkeypatch, capsys, capture)
    assert not opened, f"the command opened {opened} and waited on it"


class _Gaussian:
    """A 2-d standard normal log-probability that sends its own process SIGINT at a call."""

    ndim = 2
    bounds = np.array([[-10.0, 10.0], [-10.0, 10.0]])
    names = ["x", "y"]

    def __init__(self, interrupt_at: int):
        self.calls = self.evaluations = 0
        self.interrupt_at = interrupt_at

    def __call__(self, theta):
        import os
        import signal

        self.calls += 1
        self.evaluations += len(np.atleast_2d(theta))
        if self.calls == self.interrupt_at:
            os.kill(os.getpid(), signal.SIGINT)
        return -0.5 * np.sum(np.atleast_2d(theta) ** 2, axis=1)


def test_a_signal_inside_the_log_probability_ends_the_chain_without_a_traceback(monkeypatch,
                                                                                capsys):
    import signal

    from translucent.fitting import sampler
    from translucent.reports import cli

    monkeypatch.setattr(sampler, "find_modes", lambda model, start=None: [
        sampler.Mode(np.zeros(2), 0.0, np.eye(2))])
    previous = signal.signal(signal.SIGINT, cli._on_sigint)  # what the command line installs
    try:
        with pytest.raises(KeyboardInterrupt):
            sampler.run_chain(_Gaussian(interrupt_at=50), walkers=8, max_steps=400)
    finally:
        signal.signal(signal.SIGINT, previous)
    captured = capsys.readouterr()
    assert "emcee" not in captured.out + captured.err
    assert "Traceback" not in captured.out + captured.err


def test_an_interrupted_fit_leaves_no_output_folder(tmp_path, monkeypatch, capsys, capture):
    from translucent.fitting import fit

    (tmp_path / "c.json").write_bytes(capture["small.json"])
    (tmp_path / "small.exr").write_bytes(capture["small.exr"])

    def interrupted(path, *, out_dir, **options):
        (fit.output_folder(out_dir) / "dipole_summary.json").write_text("{}")  # half done
        raise KeyboardInterrupt

    monkeypatch.setattr(fit, "fit_capture", interrupted)
    assert main(["fit", str(tmp_path / "c.json"), "--out", str(tmp_path / "fit")]) == 130
    assert sorted(p.name for p in tmp_path.iterdir()) == ["c.json", "small.exr"]


@pytest.mark.parametrize("model, name", [("dipole", "dipole_summary.json"),
                                         ("subedit", "subedit_profile.npz")])
def test_a_fit_output_that_is_its_input_is_refused_before_any_chain(
        tmp_path, monkeypatch, capsys, capture, model, name):
    from translucent.fitting import fit, sampler

    folder = tmp_path / "out"
    folder.mkdir()
    (folder / name).write_bytes(capture["small.json"])  # the capture, named as an output
    (folder / "small.exr").write_bytes(capture["small.exr"])
    before = {p.name: p.read_bytes() for p in folder.iterdir()}

    def no_chain(*args, **kwargs):
        raise AssertionError("a chain ran before the outputs were checked")

    monkeypatch.setattr(sampler, "run_chain", no_chain)
    monkeypatch.setattr(fit, "run_chain", no_chain)
    assert main(["fit", str(folder / name), "--model", model, "--out", str(folder)]) == 2
    err = capsys.readouterr().err
    assert "is the input capture" in err and "Traceback" not in err
    assert {p.name: p.read_bytes() for p in folder.iterdir()} == before


def test_the_fit_writes_exactly_the_files_it_names_beforehand(tmp_path):
    from translucent.fitting.capture import read_capture, write_capture
    from translucent.fitting.fit import fit_dipole, output_names, write_outputs
    from translucent.fitting.synthetic import dipole_capture
    from translucent.materials import measured_medium

    pixels, spec = dipole_capture(measured_medium("Skin1"), size=24, seed=1)
    data = read_capture(write_capture(tmp_path / "c.json", pixels, spec))
    result = fit_dipole(data, seed=1, walkers=16, max_steps=200)
    written = write_outputs(result, tmp_path / "fit")
    assert sorted(p.name for p in written.values()) == sorted(output_names("dipole"))
