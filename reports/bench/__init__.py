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
    if not width:
        return scene
    camera = scene.camera
    return with_size(scene, width, max(1, round(width * camera.height / camera.width)))


def with_size(scene, width: int, height: int):
    """Return ``scene`` with its camera resized to ``width`` x ``height`` pixels.

    Parameters
    ----------
    scene : Scene
    width, height : int
        Image size in pixels.

    Returns
    -------
    Scene
        The same scene and camera pose, another film size.
    """
    from dataclasses import replace

    return scene.with_camera(replace(scene.camera, width=width, height=height))
