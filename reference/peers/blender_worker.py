r"""Render a scene description with Blender Cycles: run by the Python that has ``bpy``.

Usage: ``python -I blender_worker.py DESCRIPTION.json`` (isolated: this folder's modules
must not shadow Blender's), or in Blender itself: ``blender --background --python
blender_worker.py -- DESCRIPTION.json``. The description (written by
:func:`translucent.reference.peers.blender.describe_scene`) holds the camera, the triangle
meshes with their materials, the lights, the renders (samples and seed each) and the output
folder; every render is written there as ``render_<k>.npy`` (float32, H x W x 3, row 0 at
the top), with ``timing.json``. This file imports nothing of the suite (the ``bpy`` wheel
pins a numpy the suite does not use), so the two renderers share no code.

Cycles' conventions (``intern/cycles``, Blender 4.2 to 5.0), stated where they are used:

* a material with a volume output and no surface output is a boundary of index 1 around
  a homogeneous medium; Volume Scatter gives :math:`\sigma_s = \text{color} \cdot
  \text{density}`, Volume Absorption :math:`\sigma_a = (1 - \text{color})\,\text{density}`;
  a Glass BSDF of roughness 0 on the same material is a smooth dielectric boundary (exact
  unpolarised Fresnel);
* the Principled BSDF's subsurface radius is ``Radius x Scale``, divided by
  :math:`4\pi` for Burley and Random Walk (``bssrdf_setup_radius``): the reduced mean
  free path :math:`1/\sigma'_t` of the walk, :math:`\sigma_t = \sigma'_t/(1-g)`; the
  Base Color is the surface albedo the walk's single-scattering albedo is fitted to;
  IOR 1 exactly has no specular layer;
* lights, with ``normalize`` on: a point or spot light of ``energy`` P watts and radius 0
  has intensity :math:`P/(4\pi)`; with radius r and no soft fall-off it is a sphere of
  radiance :math:`P/(4\pi^2 r^2)`; a spot's ``spot_size`` is the full cone angle (its own
  edge, a smoothstep in the cosine over ``spot_blend``, is replaced by the suite's linear
  ramp in angle, made in the light's node tree from its Texture Coordinate ``Normal``, the
  direction of emission); an area light of power P and area A
  is one-sided with radiance :math:`P/(\pi A)` along its local -z; a sun of strength S
  and angle 0 gives irradiance S; the world's colour times strength is its radiance;
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


def _dielectric_medium_material(name, sigma_s, sigma_a, g, ior):
    """Return the medium inside a smooth dielectric boundary (Glass BSDF, roughness 0)."""
    return _with_glass_boundary(_medium_material(name, sigma_s, sigma_a, g), ior)


def _with_glass_boundary(material, ior):
    """Give a medium's material the surface of a smooth dielectric of index ``ior``."""
    nodes, links = material.node_tree.nodes, material.node_tree.links
    glass = nodes.new("ShaderNodeBsdfGlass")
    glass.distribution = "GGX"  # roughness 0: the singular (perfectly specular) path
    glass.inputs["Roughness"].default_value = 0.0
    glass.inputs["IOR"].default_value = ior
    glass.inputs["Color"].default_value = [1.0, 1.0, 1.0, 1.0]
    output = next(node for node in nodes if node.bl_idname == "ShaderNodeOutputMaterial")
    links.new(glass.outputs[0], output.inputs["Surface"])
    return material


def _subsurface_material(name, spec):
    """Principled BSDF, all subsurface: base colour A, radius in scene units, scale 1."""
    material, nodes, links, output = _node_material(name)
    principled = nodes.new("ShaderNodeBsdfPrincipled")
    principled.subsurface_method = spec["method"]
    values = {"Subsurface Weight": 1.0, "Subsurface Scale": 1.0,
              **({"Base Color": list(spec["base_color"]) + [1.0],
                  "Subsurface Radius": list(spec["radius"])} if "radius" in spec else {}),
              "Subsurface Anisotropy": spec["anisotropy"], "IOR": spec["ior"],
              "Subsurface IOR": spec["ior"], "Roughness": 0.0, "Metallic": 0.0,
              "Specular IOR Level": 0.5,  # 0.5: the IOR as given
              "Coat Weight": 0.0, "Sheen Weight": 0.0}
    per_face = {"Base Color": "face_base_color", "Subsurface Radius": "face_radius"}
    for socket in principled.inputs:  # by name: a mode's unused sockets are not keyed
        if per_face.get(socket.name) in spec:
            attribute = nodes.new("ShaderNodeAttribute")
            attribute.attribute_type = "GEOMETRY"
            attribute.attribute_name = per_face[socket.name]
            out = "Color" if socket.name == "Base Color" else "Vector"
            links.new(attribute.outputs[out], socket)
        elif socket.name in values:
            socket.default_value = values[socket.name]
    links.new(principled.outputs[0], output.inputs["Surface"])
    return material


def _value(node_tree, kind, operation, *inputs):
    """Add a Math or Vector Math node of ``operation``; inputs are sockets or constants."""
    node = node_tree.nodes.new(kind)
    node.operation = operation
    sockets = [socket for socket in node.inputs if socket.enabled]
    for socket, value in zip(sockets, inputs, strict=False):  # constants fill the rest
        if hasattr(value, "is_output"):
            node_tree.links.new(value, socket)
        else:
            socket.default_value = value
    return node.outputs[0]


def _grid_image(name, grid):
    """Return a float image of the (Z, Y, X, 3) grid as an atlas: z slices side by side."""
    depth, rows, columns, _ = grid.shape
    image = bpy.data.images.new(name, width=columns * depth, height=rows, alpha=True,
                                float_buffer=True)
    image.colorspace_settings.name = "Non-Color"
    atlas = np.ones((rows, depth * columns, 4), dtype=np.float32)
    # image rows run from the bottom, as the voxel rows (y) up the grid
    atlas[:, :, :3] = grid.transpose(1, 0, 2, 3).reshape(rows, depth * columns, 3)
    image.pixels.foreach_set(atlas.ravel())
    image.pack()
    return image


def _solid_medium_material(name, spec):
    """Return a medium read from a voxel grid, nearest voxel, clamped at the box.

    The grid's voxel (x, y, z) of the box ``bounds`` is found from the object coordinates
    (the meshes are given in world coordinates, so object and world agree) and read from
    an atlas image with Closest interpolation at its pixel's centre.
    """
    material, nodes, links, output = _node_material(name)
    tree = material.node_tree
    sigma_s, sigma_a = spec["sigma_s"], spec["sigma_a"]
    depth, rows, columns, _ = sigma_s.shape
    low, high = (np.asarray(b, dtype=np.float64) for b in spec["bounds"])
    coordinates = nodes.new("ShaderNodeTexCoord").outputs["Object"]
    vector = "ShaderNodeVectorMath"
    scale = [float(n) / float(h - lo)
             for n, h, lo in zip((columns, rows, depth), high, low, strict=True)]
    index = _value(tree, vector, "SUBTRACT", coordinates, list(low))
    index = _value(tree, vector, "MULTIPLY", index, scale)
    index = _value(tree, vector, "FLOOR", index)
    index = _value(tree, vector, "MAXIMUM", index, [0.0, 0.0, 0.0])
    index = _value(tree, vector, "MINIMUM", index, [columns - 1.0, rows - 1.0, depth - 1.0])
    split = nodes.new("ShaderNodeSeparateXYZ")
    links.new(index, split.inputs[0])
    x, y, z = split.outputs["X"], split.outputs["Y"], split.outputs["Z"]
    math_node = "ShaderNodeMath"
    u = _value(tree, math_node, "MULTIPLY_ADD", z, float(columns), x)
    u = _value(tree, math_node, "ADD", u, 0.5)
    u = _value(tree, math_node, "DIVIDE", u, float(columns * depth))
    v = _value(tree, math_node, "ADD", y, 0.5)
    v = _value(tree, math_node, "DIVIDE", v, float(rows))
    uv = nodes.new("ShaderNodeCombineXYZ")
    links.new(u, uv.inputs["X"])
    links.new(v, uv.inputs["Y"])
    scatter = nodes.new("ShaderNodeVolumeScatter")
    absorb = nodes.new("ShaderNodeVolumeAbsorption")
    for shader, grid, complement in ((scatter, sigma_s, False), (absorb, sigma_a, True)):
        density = max(float(grid.max()), 1e-12)
        texture = nodes.new("ShaderNodeTexImage")
        texture.image = _grid_image(f"{name}_{shader.name}", grid / density)
        texture.interpolation = "Closest"
        texture.extension = "EXTEND"
        links.new(uv.outputs[0], texture.inputs["Vector"])
        color = texture.outputs["Color"]
        if complement:  # Volume Absorption takes sigma_a = (1 - color) density
            color = _value(tree, vector, "SUBTRACT", [1.0, 1.0, 1.0], color)
        links.new(color, shader.inputs["Color"])
        shader.inputs["Density"].default_value = density
    scatter.inputs["Anisotropy"].default_value = 0.0
    add = nodes.new("ShaderNodeAddShader")
    links.new(scatter.outputs[0], add.inputs[0])
    links.new(absorb.outputs[0], add.inputs[1])
    links.new(add.outputs[0], output.inputs["Volume"])
    return _with_glass_boundary(material, spec["ior"]) if spec["ior"] != 1.0 else material


def _face_attributes(mesh, spec):
    """Store a subsurface material's per-face inputs on ``mesh`` as face attributes."""
    for key, kind, field in (("face_base_color", "FLOAT_COLOR", "color"),
                             ("face_radius", "FLOAT_VECTOR", "vector")):
        if key not in spec:
            continue
        values = np.asarray(spec[key], dtype=np.float32)
        if kind == "FLOAT_COLOR":
            values = np.concatenate([values, np.ones((len(values), 1), np.float32)], axis=1)
        attribute = mesh.attributes.new(key, kind, "FACE")
        attribute.data.foreach_set(field, values.ravel())


def _diffuse_material(name, albedo):
    material, nodes, links, output = _node_material(name)
    diffuse = nodes.new("ShaderNodeBsdfDiffuse")
    diffuse.inputs["Color"].default_value = list(albedo) + [1.0]
    links.new(diffuse.outputs[0], output.inputs["Surface"])
    return material


def _spot_falloff(light, cutoff, beam_width):
    """Multiply the spot's emission by 1 inside the beam, linear in angle to 0 at the cutoff.

    A light's Texture Coordinate ``Normal`` is the direction of emission in the light's
    frame, which looks down its -z: the angle off the axis is ``acos(-z)``.
    """
    light.use_nodes = True
    tree = light.node_tree
    emission = next(n for n in tree.nodes if n.bl_idname == "ShaderNodeEmission")
    direction = tree.nodes.new("ShaderNodeSeparateXYZ")
    tree.links.new(tree.nodes.new("ShaderNodeTexCoord").outputs["Normal"], direction.inputs[0])
    math_node = "ShaderNodeMath"
    cosine = _value(tree, math_node, "MULTIPLY", direction.outputs["Z"], -1.0)
    angle = _value(tree, math_node, "ARCCOSINE", cosine)
    ramp = _value(tree, math_node, "SUBTRACT", cutoff, angle)
    ramp = _value(tree, math_node, "DIVIDE", ramp, max(cutoff - beam_width, 1e-12))
    ramp = _value(tree, math_node, "MINIMUM", ramp, 1.0)
    ramp = _value(tree, math_node, "MAXIMUM", ramp, 0.0)
    tree.links.new(ramp, emission.inputs["Strength"])


def _add_light(scene, world, index, spec):
    """Add one light of the description (kinds and units: the module docstring)."""
    kind = spec["type"]
    if kind == "environment":
        background = world.node_tree.nodes["Background"]
        peak = max(max(spec["radiance"]), 1e-30)
        background.inputs["Color"].default_value = [c / peak for c in spec["radiance"]] + [1.0]
        background.inputs["Strength"].default_value = peak
        return
    light = bpy.data.lights.new(f"light_{index}", type=kind.upper())
    power = spec["energy"] if kind != "sun" else spec["strength"]
    peak = max(max(power), 1e-30)
    light.energy = peak
    if kind == "sun":
        light.angle = 0.0  # a delta light
    light.color = [p / peak for p in power]
    if hasattr(light, "normalize"):
        light.normalize = True
    if kind in ("point", "spot"):
        light.shadow_soft_size = float(spec.get("radius", 0.0))
        if hasattr(light, "use_soft_falloff"):  # a true sphere light, not the soft fall-off
            light.use_soft_falloff = False
    if kind == "spot":
        light.spot_size = 2.0 * float(spec["cutoff"])
        light.spot_blend = 0.0  # a hard cone: the fall-off is the node tree's
        light.show_cone = False
        _spot_falloff(light, float(spec["cutoff"]), float(spec["beam_width"]))
    if kind == "area":
        light.shape = "RECTANGLE"
        light.size = float(spec["size_x"])
        light.size_y = float(spec["size_y"])
        light.spread = math.pi  # a Lambertian emitter
    holder = bpy.data.objects.new(f"light_{index}", light)
    # an emitter with an area is seen by the camera, as the suite's shapes that emit are
    # (Cycles hides lights from the camera by default)
    holder.visible_camera = kind == "area" or float(spec.get("radius", 0.0)) > 0.0
    if "matrix" in spec:
        holder.matrix_world = Matrix(spec["matrix"])
    else:
        holder.location = spec["position"]
    scene.collection.objects.link(holder)


def build(description):
    """Make the Blender scene of ``description`` and return it, set up for Cycles."""
    _clear()
    scene = bpy.context.scene
    scene.render.engine = "CYCLES"
    cycles = scene.cycles
    cycles.device = "CPU"
    cycles.use_denoising = False
    cycles.use_adaptive_sampling = False
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
        if material["type"] == "medium" and material.get("ior", 1.0) != 1.0:
            mesh.materials.append(_dielectric_medium_material(
                spec["name"], material["sigma_s"], material["sigma_a"], material["g"],
                material["ior"]))
        elif material["type"] == "medium":
            mesh.materials.append(_medium_material(spec["name"], material["sigma_s"],
                                                   material["sigma_a"], material["g"]))
        elif material["type"] == "subsurface":
            _face_attributes(mesh, material)
            mesh.materials.append(_subsurface_material(spec["name"], material))
        elif material["type"] == "solid_medium":
            mesh.materials.append(_solid_medium_material(spec["name"], material))
        elif material["type"] == "diffuse":
            mesh.materials.append(_diffuse_material(spec["name"], material["albedo"]))
        else:
            raise ValueError(f"unknown material type {material['type']!r}")
        item = bpy.data.objects.new(spec["name"], mesh)
        scene.collection.objects.link(item)
    for index, spec in enumerate(description["lights"]):
        _add_light(scene, world, index, spec)
    scene.render.image_settings.file_format = "OPEN_EXR"
    scene.render.image_settings.color_depth = "32"
    scene.render.image_settings.color_mode = "RGB"
    scene.view_settings.view_transform = "Standard"
    return scene


def main(path):
    """Render every render of the description at ``path`` into its output folder.

    ``renders``: a list of ``{"samples": N, "seed": S}``, written as ``render_<k>.npy``
    with their seconds in ``timing.json``.
    """
    with open(path) as handle:
        description = json.load(handle)
    for item in description["objects"]:  # arrays live beside the description
        for key, value in item["material"].items():
            if isinstance(value, dict) and "npy" in value:
                item["material"][key] = np.load(os.path.join(os.path.dirname(path),
                                                             value["npy"]))
    scene = build(description)
    out = description["output"]
    os.makedirs(out, exist_ok=True)
    seconds = []
    if description.get("warm_up"):  # untimed: loads the kernels and builds the BVH once
        scene.cycles.samples = 1
        scene.render.filepath = os.path.join(out, "warm_up.exr")
        bpy.ops.render.render(write_still=False)
    for k, render in enumerate(description["renders"]):
        scene.cycles.samples = int(render["samples"])
        scene.cycles.seed = int(render["seed"])
        exr = os.path.join(out, f"render_{k}.exr")
        scene.render.filepath = exr
        start = time.perf_counter()
        bpy.ops.render.render(write_still=True)
        seconds.append(time.perf_counter() - start)
        image = bpy.data.images.load(exr)
        width, height = image.size
        pixels = np.array(image.pixels[:], dtype=np.float32).reshape(height, width, -1)
        bpy.data.images.remove(image)
        np.save(os.path.join(out, f"render_{k}.npy"), pixels[::-1, :, :3].copy())
        os.remove(exr)
    if description.get("save_blend"):
        bpy.ops.wm.save_as_mainfile(filepath=description["save_blend"], check_existing=False)
    with open(os.path.join(out, "timing.json"), "w") as handle:
        json.dump({"seconds": seconds, "blender": bpy.app.version_string}, handle)


if __name__ == "__main__":
    # ``python -I blender_worker.py FILE`` or ``blender --background --python it -- FILE``
    main(sys.argv[sys.argv.index("--") + 1] if "--" in sys.argv else sys.argv[1])
