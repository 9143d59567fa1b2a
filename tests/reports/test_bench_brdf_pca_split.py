"""``translucent bench brdf_pca --split``: BRDF editing's error on ``glossy`` by its parts."""

import json
import math

from smoke import explain, run_command


def test_the_split_names_the_lambertian_gather_as_the_dominant_part(tmp_path):
    """Through the console script, quick (64 gather samples): the chain of models comes
    from the committed references, whatever the method's knobs, and the Lambertian gather
    (0.0245 against a PCA step within noise) is named the dominant part."""
    out = tmp_path / "split.json"
    result = run_command("bench", "brdf_pca", "--quick", "--split", "--no-progress",
                         "--json", out, "--out", tmp_path / "figures", cwd=tmp_path)
    assert result.returncode == 0 and "Traceback" not in result.stderr, explain(result)
    assert "dominant: Lambertian gather samples" in result.stdout, explain(result)
    scenes = json.loads(out.read_text())["split"]["scenes"]
    assert list(scenes) == ["glossy"]  # quick: the first scene alone
    split = scenes["glossy"]
    models = split["models"]
    assert models["brdf_pca_k6+lambertian_gather2"]["against"] == "brdf_pca_k6"
    # the gather transport holds the model's error; the PCA of the BRDFs does not
    assert models["brdf_pca_k6+lambertian_gather2"]["relative_mse"] > 0.01
    assert abs(models["brdf_pca_k6"]["relative_mse"]) < 1e-3
    # gather samples that reflect their direct light by their BRDF: a model nearer the
    # exact one
    assert models["brdf_pca_k6+glossy_gather2"]["to_exact"] < \
        0.5 * models["brdf_pca_k6+lambertian_gather2"]["to_exact"]
    assert [row["model"] for row in split["rows"]] == \
        ["brdf_pca_k6+lambertian_gather2"] * 3 + ["brdf_pca_k6+glossy_gather2"] * 2
    for row in split["rows"]:
        assert row["knobs"]["gather_samples"] == 64
        assert all(math.isfinite(value) for value in row["to_model"].values())
        assert row["relit_frame_seconds"] > 0
    assert split["parts"]["dominant"] == "Lambertian gather samples"
    assert 0 < split["edge_pixels"] < split["pixels"]
