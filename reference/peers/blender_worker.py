r"""Render a scene description with Blender Cycles: run by the Python that has ``bpy``.

Usage: ``python -I blender_worker.py DESCRIPTION.json`` (isolated: this folder's modules
must not shadow Blender's). The description (written by
:func:`translucent.reference.peers.blender.describe_scene`) holds the camera, the triangle
meshes with their materials, the point lights, the sample count, the seeds and the output
folder; every pass is written there as ``pass_<k>.npy`` (float32, H x W x 3, row 0 at the top) and
``timing.json``. This file imports nothing of the suite (the ``bpy`` wheel pins a numpy
the suite does not use), so the two renderers share no code.

Cycles' conventions, stated where they are used:

* a material with a volume output and no surface output is a boundary of index 1 around
  a homogeneous medium; Volume Scatter gives :math:`\sigma_s = \text{color} \cdot
  \text{density}`, Volume Absorption :math:`\sigma_a = (1 - \text{color})\,\text{density}`;
* a point light of ``energy`` W and radius 0; its intensity in the suite's units is
  measured, not assumed, by the Lambertian calibration of the caller;
* the camera's horizontal field of view is ``angle`` with ``sensor_fit = 'HORIZONTAL'``;
  a box pixel filter one pixel wide, as the suite's sensor.
"""

import json
import math
import os
import sys
import time

import bpy
import numpy as np
from mathutils import Matrix, Vector


def _clear():
    # the start-up file's cube, light and camera go; factory settings would drop Cycles
    for item in list(bpy.data.objects):
        bpy.data.objects.remove(item, do_unlink=True)


def _look_at(origin, target, up):
    forward = (Vector(target) - Vector(origin)).normalized()
    right = forward.cross(Vector(up)).normalized()
    true_up = right.cross(forward)
    # Blender cameras look down their local -z with +y up
    rotation = Matrix((right, true_up, -forward)).transposed()
    return Matrix.Translation(Vector(origin)) @ rotation.to_4x4()


def _node_material(name):
    """Return a new material whose node tree holds its output alone, and its parts."""
    material = bpy.data.materials.new(name)
    material.use_nodes = True
    nodes, links = material.node_tree.nodes, material.node_tree.links
    nodes.clear()
    return material, nodes, links, nodes.new("ShaderNodeOutputMaterial")


def _medium_material(name, sigma_s, sigma_a, g):
    material, nodes, links, output = _node_material(name)
    scatter = nodes.new("ShaderNodeVolumeScatter")
    absorb = nodes.new("ShaderNodeVolumeAbsorption")
    add = nodes.new("ShaderNodeAddShader")
    density_s = max(max(sigma_s), 1e-12)
    density_a = max(max(sigma_a), 1e-12)
    scatter.inputs["Color"].default_value = [s / density_s for s in sigma_s] + [1.0]
    scatter.inputs["Density"].default_value = density_s
    scatter.inputs["Anisotropy"].default_value = g
    absorb.inputs["Color"].default_value = [1.0 - a / density_a for a in sigma_a] + [1.0]
    absorb.inputs["Density"].default_value = density_a
    links.new(scatter.outputs[0], add.inputs[0])
    links.new(absorb.outputs[0], add.inputs[1])
    links.new(add.outputs[0], output.inputs["Volume"])
    if hasattr(material.cycles, "homogeneous_volume"):  # before Blender 5 it was asked for
        material.cycles.homogeneous_volume = True
    return material


def _diffuse_material(name, albedo):
    material, nodes, links, output = _node_material(name)
    diffuse = nodes.new("ShaderNodeBsdfDiffuse")
    diffuse.inputs["Color"].default_value = list(albedo) + [1.0]
    links.new(diffuse.outputs[0], output.inputs["Surface"])
    return material


def build(description):
    """Make the Blender scene of ``description`` and return it, set up for Cycles."""
    _clear()
    scene = bpy.context.scene
    scene.render.engine = "CYCLES"
    cycles = scene.cycles
    cycles.device = "CPU"
    cycles.use_denoising = False
    cycles.use_adaptive_sampling = False
    cycles.samples = int(description["samples"])
    for bounces in ("max_bounces", "diffuse_bounces", "glossy_bounces", "transmission_bounces",
                    "volume_bounces", "transparent_max_bounces"):
        setattr(cycles, bounces, 4096)
    cycles.sample_clamp_direct = 0.0
    cycles.sample_clamp_indirect = 0.0
    cycles.pixel_filter_type = "BOX"
    cycles.filter_width = 1.0
    cycles.caustics_reflective = True
    cycles.caustics_refractive = True
    cycles.blur_glossy = 0.0
    scene.render.threads_mode = "FIXED"
    scene.render.threads = int(description.get("threads", os.cpu_count() or 1))
    world = bpy.data.worlds.new("black")
    world.use_nodes = True
    world.node_tree.nodes["Background"].inputs["Strength"].default_value = 0.0
    scene.world = world
    camera_spec = description["camera"]
    scene.render.resolution_x = int(camera_spec["width"])
    scene.render.resolution_y = int(camera_spec["height"])
    scene.render.resolution_percentage = 100
    scene.render.pixel_aspect_x = scene.render.pixel_aspect_y = 1.0
    camera_data = bpy.data.cameras.new("camera")
    camera_data.sensor_fit = "HORIZONTAL"
    camera_data.angle = math.radians(float(camera_spec["fov_x_degrees"]))
    camera_data.clip_start = float(camera_spec.get("clip_start", 1e-3))
    camera_data.clip_end = float(camera_spec.get("clip_end", 1e6))
    camera = bpy.data.objects.new("camera", camera_data)
    camera.matrix_world = _look_at(camera_spec["origin"], camera_spec["target"],
                                   camera_spec["up"])
    scene.collection.objects.link(camera)
    scene.camera = camera
    for spec in description["objects"]:
        mesh = bpy.data.meshes.new(spec["name"])
        mesh.from_pydata([tuple(v) for v in spec["vertices"]], [],
                         [tuple(f) for f in spec["faces"]])
        mesh.update()
        material = spec["material"]
        if material["type"] == "medium":
            mesh.materials.append(_medium_material(spec["name"], material["sigma_s"],
                                                   material["sigma_a"], material["g"]))
        elif material["type"] == "diffuse":
            mesh.materials.append(_diffuse_material(spec["name"], material["albedo"]))
        else:
            raise ValueError(f"unknown material type {material['type']!r}")
        item = bpy.data.objects.new(spec["name"], mesh)
        scene.collection.objects.link(item)
    for index, spec in enumerate(description["lights"]):
        light = bpy.data.lights.new(f"light_{index}", type="POINT")
        peak = max(spec["energy"])
        light.energy = peak
        light.color = [e / peak for e in spec["energy"]]
        light.shadow_soft_size = 0.0
        holder = bpy.data.objects.new(f"light_{index}", light)
        holder.location = spec["position"]
        scene.collection.objects.link(holder)
    scene.render.image_settings.file_format = "OPEN_EXR"
    scene.render.image_settings.color_depth = "32"
    scene.render.image_settings.color_mode = "RGB"
    scene.view_settings.view_transform = "Standard"
    return scene


def main(path):
    """Render every pass of the description at ``path`` into its output folder."""
    with open(path) as handle:
        description = json.load(handle)
    scene = build(description)
    out = description["output"]
    os.makedirs(out, exist_ok=True)
    seconds = []
    for k, seed in enumerate(description["seeds"]):
        scene.cycles.seed = int(seed)
        exr = os.path.join(out, f"pass_{k}.exr")
        scene.render.filepath = exr
        start = time.perf_counter()
        bpy.ops.render.render(write_still=True)
        seconds.append(time.perf_counter() - start)
        image = bpy.data.images.load(exr)
        width, height = image.size
        pixels = np.array(image.pixels[:], dtype=np.float32).reshape(height, width, -1)
        bpy.data.images.remove(image)
        np.save(os.path.join(out, f"pass_{k}.npy"), pixels[::-1, :, :3].copy())
        os.remove(exr)
    with open(os.path.join(out, "timing.json"), "w") as handle:
        json.dump({"seconds": seconds, "blender": bpy.app.version_string}, handle)


if __name__ == "__main__":
    main(sys.argv[1])
