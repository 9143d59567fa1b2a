"""``translucent capture`` and ``translucent fit`` with every model, through the console script.

The capture command makes a 24-pixel dipole capture of Skin1; each fit model samples it
with short chains (16 walkers, 200 steps: too few to converge, which the fit says with
exit 1, as the documentation promises) and writes its summary, material file and plots.
The fast tier fits the dipole (:data:`FAST_TIER`); the slow tier every model.
"""

import json

import pytest
from smoke import explain, run_command, run_ok

#: The fit models of ``translucent fit --model``.
FIT_MODELS = ("dipole", "walk", "subedit", "both", "better_dipole", "quantized_diffusion",
              "photon_beam_diffusion", "burley_searchlight", "burley_transmission",
              "burley_dmfp", "burley_cycles")

#: The model the fast tier fits: the dipole, the default. SubEdit, the walk's table and a
#: named profile are fitted in the fast tier by ``bench fitting --quick`` and in-process by
#: tests/fitting (each named profile's reduced table in test_named_models.py); their fits
#: through the command line (8-19 s each on a fresh environment) run in the slow tier.
FAST_TIER = ("dipole",)


def test_the_models_are_those_the_fit_command_offers():
    from translucent.fitting.named_models import NAMED_MODELS

    assert set(FIT_MODELS) == {"dipole", "walk", "subedit", "both", *NAMED_MODELS}


@pytest.fixture(scope="module")
def capture(tmp_path_factory):
    """The capture command's run: a 24-pixel dipole capture of Skin1."""
    folder = tmp_path_factory.mktemp("smoke_capture")
    result = run_command("capture", "skin1", "--generator", "dipole", "--size", "24",
                         "--out", folder / "skin1.json", cwd=folder)
    return folder, result


def test_capture(capture):
    folder, result = capture
    assert result.returncode == 0, explain(result)
    sidecar = json.loads((folder / "skin1.json").read_text())
    assert (folder / sidecar["image"]).is_file()


@pytest.mark.parametrize("model", [model if model in FAST_TIER else
                                   pytest.param(model, marks=pytest.mark.slow)
                                   for model in FIT_MODELS])
def test_fit_with_every_model(capture, tmp_path, model):
    folder, made = capture
    assert made.returncode == 0, explain(made)
    # a chain cut short is exit 1, and says so
    result = run_ok("fit", folder / "skin1.json", "--model", model, "--walkers", "16",
                    "--max-steps", "200", "--segments", "2", "--out", tmp_path / "f",
                    cwd=tmp_path, codes=(1,))
    assert "NOT converged" in result.stdout, explain(result)
    fitted = {"both": ("dipole", "subedit")}.get(model, (model,))
    for name in fitted:
        assert json.loads((tmp_path / "f" / f"{name}_summary.json").read_text())
        assert (tmp_path / "f" / f"{name}_material.toml").is_file()
        assert (tmp_path / "f" / f"{name}_profile.png").read_bytes()[:4] == b"\x89PNG"
        corners = list((tmp_path / "f").glob(f"{name}_corner*.png"))  # SubEdit: one a channel
        assert corners and all(path.read_bytes()[:4] == b"\x89PNG" for path in corners)
