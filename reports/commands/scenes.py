"""List the built-in scenes, one line each (``name: description``).

``--show SCENE`` describes one scene (objects, vertex counts, materials, lights, camera)
without rendering it.
"""

from __future__ import annotations


def add_arguments(parser):
    """``--show SCENE`` (a built-in name or a scene file)."""
    parser.add_argument("--show", metavar="SCENE", default=None,
                        help="describe one scene (built-in name or path to a TOML file)")


def run(args) -> int:
    """Print the catalogue, or the summary of one scene."""
    from ...scenes import builtin_scene_descriptions, load_scene
    from .record import record

    if args.show is None:
        descriptions = builtin_scene_descriptions()
        width = max((len(name) for name in descriptions), default=0)
        for name, description in descriptions.items():
            print(f"{name + ':':<{width + 1}} {description}")
        record(args, scenes=[{"name": name, "description": description}
                             for name, description in descriptions.items()])
        return 0
    scene = load_scene(args.show)
    camera = scene.camera
    print(f"{scene.name}: {scene.description}")
    print(f"  source: {scene.source}")
    print(f"  mm_per_unit: {scene.mm_per_unit:g}")
    print(f"  camera: {camera.width} x {camera.height}, fov {camera.fov:g} deg, "
          f"origin {camera.origin.tolist()}, target {camera.target.tolist()}")
    for item in scene.objects:
        mesh = item.mesh
        material = item.material
        label = " ".join(filter(None, [type(material).__name__, getattr(material, "name", "")]))
        print(f"  object {item.name}: {len(mesh.vertices)} vertices, {len(mesh.faces)} faces, "
              f"area {mesh.area * scene.mm_per_unit ** 2:.4g} mm^2, "
              f"{label}")
    for light in scene.lights:
        print(f"  light {type(light).__name__}")
    record(args, scene={
        "name": scene.name, "description": scene.description, "source": str(scene.source),
        "mm_per_unit": scene.mm_per_unit,
        "camera": {"width": camera.width, "height": camera.height, "fov": camera.fov,
                   "origin": camera.origin, "target": camera.target},
        "objects": [{"name": item.name, "vertices": len(item.mesh.vertices),
                     "faces": len(item.mesh.faces),
                     "area_mm2": item.mesh.area * scene.mm_per_unit ** 2,
                     "material": type(item.material).__name__,
                     "material_name": getattr(item.material, "name", None)}
                    for item in scene.objects],
        "lights": [type(light).__name__ for light in scene.lights]})
    return 0
