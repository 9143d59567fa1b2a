"""Benchmarks, one module each (``translucent bench <module>``)."""


def at_width(scene, width: int):
    """Return ``scene`` seen ``width`` pixels wide, the height following its aspect.

    Parameters
    ----------
    scene : Scene
    width : int
        Image width in pixels; 0 keeps the scene's own size.

    Returns
    -------
    Scene
        The same scene with a camera of ``width`` x ``round(width * height / width)``
        pixels (at least 1 high), or ``scene`` itself for width 0.
    """
    from dataclasses import replace

    if not width:
        return scene
    camera = scene.camera
    height = max(1, round(width * camera.height / camera.width))
    return scene.with_camera(replace(camera, width=width, height=height))
