"""The geometry correction as the methods apply it (fast/object_geometry.py)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from translucent.fast import prt, splatting
from translucent.fast.conformance import tiny_sphere_text
from translucent.fast.object_geometry import QUICK_GEOMETRY_KNOBS
from translucent.fast.radiosity.diffusion_escape import finite_object_gain
from translucent.materials.dipole import total_diffuse_reflectance
from translucent.scenes import Mesh, loads_scene
from translucent.scenes.meshes import icosphere
from translucent.scenes.object_diffusion import diffusion_correction, object_diffusion

#: Marble and Skin1 (Jensen et al. 2001, Table 1), mm^-1.
MEDIA = {"Marble": ([0.0021, 0.0041, 0.0071], [2.19, 2.62, 3.0]),
         "Skin1": ([0.032, 0.17, 0.48], [0.74, 0.88, 1.01])}


@pytest.mark.parametrize("medium", [
    "Marble", pytest.param("Skin1", marks=pytest.mark.slow)])  # one medium fast: 2 s each
def test_the_energy_it_adds_is_the_escape_probabilitys_gain(medium):
    """A second estimator: radiosity's finite-object gain solves the adjoint problem (the
    escape probability from the dipole's source, not the field from it) on its own."""
    sigma_a, sigma_s_prime = (np.array(v) for v in MEDIA[medium])
    mesh = icosphere(4, 10.0)
    triangles = mesh.vertices[mesh.faces]
    diffusion = object_diffusion(triangles, cells=4000, clusters=192)
    response = diffusion.response(sigma_a, sigma_s_prime, 1.3)
    area = 0.5 * np.linalg.norm(np.cross(triangles[:, 1] - triangles[:, 0],
                                         triangles[:, 2] - triangles[:, 0]), axis=1).sum()
    added = response.sum(axis=0) * area / diffusion.clusters
    total = total_diffuse_reflectance(sigma_a, sigma_s_prime, 1.3)
    gain = finite_object_gain(diffusion.grid, diffusion.cluster_point,
                              diffusion.cluster_normal, sigma_a, sigma_s_prime, 1.3)
    ratio = np.median((total + added) / total / gain, axis=0)
    # where the grid resolves the diffusion length (two voxels or more; Skin1's blue is
    # 0.7 mm against 1 mm voxels)
    sigma_tr = np.sqrt(3.0 * sigma_a * (sigma_a + sigma_s_prime))
    resolved = 1.0 / sigma_tr > 2.0 * diffusion.grid.voxel_size
    assert resolved.any()
    np.testing.assert_allclose(ratio[resolved], 1.0, atol=0.03)
    assert np.all(np.median(gain, axis=0)[resolved] > 1.0)


def _sphere_scene():
    return loads_scene(tiny_sphere_text(size=16))


def test_prts_clusters_carry_the_correction_of_every_sample():
    """The clusters against the correction solved from each illumination sample itself.

    Measured against the object's exitance (the profile's sum, what the image shows): the
    clusters' interpolation misses the sharpest part of the correction near each sample
    (a short diffusion length on a curved surface) by a few per cent of it.
    """
    state = prt.precompute(_sphere_scene(), **{**prt.QUICK_KNOBS, "geometry": "diffusion"})
    state.render()
    transfer = state.transfers[0]
    geometry, entry, exit_weights = state.geometry[transfer.name]
    material = state.scene.object(transfer.name).material
    power = state._entry_power[transfer.name]
    clustered = geometry.exitance(entry, power, exit_weights, material)
    mm = state.scene.mm_per_unit
    mesh = state.scene.object(transfer.name).mesh
    direct = np.empty_like(clustered)
    for c in range(3):
        matrix = diffusion_correction(geometry.diffusion.grid, transfer.samples.positions * mm,
                                      transfer.samples.normals, mesh.vertices * mm,
                                      mesh.normals, material.sigma_a[c],
                                      material.sigma_s_prime[c], material.eta)
        direct[:, c] = matrix @ power[:, c]
    profile = prt.brute_force_radiance(transfer, mesh.vertices, power / transfer.samples.area,
                                       material, mm_per_unit=mm)
    scale = np.linalg.norm(profile, axis=0)
    error = np.linalg.norm(clustered - direct, axis=0) / scale
    assert np.all(error < 0.06), error
    # the correction itself is not small: in red a fifth of the profile's exitance
    assert np.linalg.norm(direct[:, 0]) > 0.1 * scale[0]


def test_half_space_is_the_papers_profile_alone():
    scene = _sphere_scene()
    flat = prt.precompute(scene, **{**prt.QUICK_KNOBS, "geometry": "half_space"})
    assert flat.geometry == {}
    shaped = prt.precompute(scene, **prt.QUICK_KNOBS)
    assert set(shaped.geometry) == {"sphere"}
    assert shaped.log.notes["geometry"]["sphere"]["clusters"] == \
        QUICK_GEOMETRY_KNOBS["geometry_clusters"]
    assert shaped.render().rgb.sum() > flat.render().rgb.sum()


def test_an_open_surface_keeps_the_half_space_and_says_so():
    scene = _sphere_scene()
    mesh = scene.object("sphere").mesh
    upper = mesh.vertices[mesh.faces].mean(axis=1)[:, 2] > -0.2  # a cap: open at the bottom
    cap = Mesh(mesh.vertices, mesh.faces[upper], mesh.normals)
    opened = dataclasses.replace(scene, objects=[dataclasses.replace(scene.objects[0],
                                                                     mesh=cap)])
    state = prt.precompute(opened, **prt.QUICK_KNOBS)
    assert state.geometry == {}
    assert any("open surface" in sentence for sentence in state.log.skipped)


def test_splatting_leaves_a_deformed_mesh_with_the_half_space():
    scene = _sphere_scene()
    state = splatting.precompute(scene, **splatting.QUICK_KNOBS)
    shaped = state.render()
    mesh = scene.object("sphere").mesh
    moved = Mesh(mesh.vertices * 1.01, mesh.faces, mesh.normals)
    deformed = dataclasses.replace(scene, objects=[dataclasses.replace(scene.objects[0],
                                                                       mesh=moved)])
    image = state.render(scene=deformed)
    assert any("not the mesh" in sentence for sentence in image.metadata["skipped"])
    flat = splatting.precompute(scene, **{**splatting.QUICK_KNOBS,
                                          "geometry": "half_space"}).render()
    assert shaped.rgb.sum() > flat.rgb.sum()


@pytest.mark.slow  # 10-20 s: radiosity's scattering geometry of the Cornell block
def test_radiosity_refuses_a_geometry_correction_that_breaks_eq15_naming_the_knob(tmp_path,
                                                                                 capsys):
    from translucent.reports.cli import main

    out = tmp_path / "block.exr"
    assert main(["approx", "radiosity", "cornell_block", "--geometry", "walk",
                 "--geometry-walks", "2048", "--no-progress", "--out", str(out)]) == 2
    error = capsys.readouterr().err
    assert "geometry" in error and "Eq. 15" in error and "half_space" in error
    assert not out.exists()
