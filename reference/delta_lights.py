r"""Emitters of finite size that stand in for delta lights a path tracer cannot use.

In Mitsuba's ``volpath`` a point, spot or directional light never reaches a medium behind
a smooth ``dielectric`` boundary: the shadow ray from a scattering point is stopped by the
boundary (it is not a ``null`` surface), and a path refracted out through the boundary hits
a light of zero size with probability zero. The medium renders black. Each such light is
replaced by the nearest thing a path can hit:

* **point light** (intensity :math:`I`, W sr^-1): a sphere emitter centred on it, of
  radius :math:`r = s\,d` (:math:`s` the ``size``, :math:`d` the distance from the light to
  the nearest surface) and radiance :math:`L = I / (\pi r^2)`. A uniform sphere of that
  radiance has intensity :math:`\pi r^2 L = I` in every direction and power
  :math:`4\pi I`, and gives exactly the point light's irradiance :math:`I\cos\theta/d^2`
  at any point that sees the whole sphere; only shadows become soft (penumbra of angular
  size :math:`\approx 2s`) and the sphere is visible where it lies in view.
* **spot light** (axis intensity :math:`I`, cone ``cutoff_angle``, linear fall-off from
  ``beam_width``): the same sphere inside a black spherical shade of radius :math:`R` with
  a round opening of half-angle :math:`(\text{beam\_width} + \text{cutoff\_angle})/2`
  about the axis. Seen from afar, the opening rim covers the sphere over angles
  :math:`\pm\arcsin(r/R)` around its edge, so choosing :math:`r/R =
  \sin((\text{cutoff\_angle} - \text{beam\_width})/2)` makes the intensity fall from
  :math:`I` to 0 over the spot's own fall-off band (an S-shaped ramp, the overlap of a
  disk with the rim, instead of Mitsuba's linear one; equal at both ends and at the
  middle). The shade keeps :math:`R \le d/2`, so a narrow fall-off band forces a smaller
  sphere than a point light's (more noise). A ``beam_width`` equal to ``cutoff_angle``
  (a hard edge) is given a band of :data:`MIN_SPOT_FALLOFF_FRACTION` of the cutoff.
* **directional light** (irradiance :math:`E` normal to it): a disk of angular radius
  :math:`\alpha = \arcsin s` in the environment map (a "sun"), its radiance scaled so that
  the irradiance on a surface facing it is exactly :math:`E` on Mitsuba's map grid.

The size :math:`s` trades bias (soft shadows, a sun that is not a point) against noise
(a path must hit the emitter: the chance falls as :math:`s^2`); :data:`DEFAULT_SIZE` is
the default.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ..errors import InputError
from ..scenes import DirectionalLight, ImageEnvironment, Mesh, PointLight, Scene, SpotLight

__all__ = [
    "DEFAULT_SIZE",
    "MIN_SPOT_FALLOFF_FRACTION",
    "SHADE_FRACTION",
    "EnvironmentParts",
    "any_perpendicular",
    "nearest_surface_distance",
    "point_light_equivalent",
    "spot_light_equivalent",
    "shade_mesh",
    "lat_long_directions",
]

#: Radius of a stand-in sphere as a fraction of the distance to the nearest surface (and
#: the sine of a stand-in sun's angular radius): the penumbra stays within about 6 degrees
#: of the terminator. Noise falls slowly with size. Measured on the built-in ``sphere``
#: (Marble, radius 10 mm, point light) at 48 x 48 and 256 spp: relative standard error of
#: the object pixels 0.91 at size 0.05 (181 of 1044 object pixels received any light),
#: 0.80 at 0.1 (487 lit), 0.57 at 0.2 (796 lit). Path tracing from the camera finds the
#: light only where a path leaving the object happens to hit the stand-in, so point-lit
#: translucent references need very many samples (about 65 000 spp for 5 % at size 0.1).
DEFAULT_SIZE = 0.1

#: A spot's shade stays within this fraction of the distance to the nearest surface, so it
#: never touches the scene.
SHADE_FRACTION = 0.5

#: Narrowest fall-off band, as a fraction of the cutoff angle: a hard-edged spot light
#: (beam_width == cutoff_angle) would need an emitter of zero size.
MIN_SPOT_FALLOFF_FRACTION = 0.05

#: Width of a stand-in sun's environment map when the scene has no image environment:
#: at least this many texels across the sun disk's diameter.
SUN_TEXELS_PER_DIAMETER = 8


def any_perpendicular(direction) -> np.ndarray:
    """Return a unit vector perpendicular to ``direction`` (an "up" for a look-at frame)."""
    direction = np.asarray(direction, dtype=np.float64)
    helper = np.array([0.0, 1.0, 0.0]) if abs(direction[1]) < 0.9 else np.array([1.0, 0, 0])
    perpendicular = np.cross(direction, helper)
    return perpendicular / np.linalg.norm(perpendicular)


def nearest_surface_distance(scene: Scene, point) -> float:
    """Distance (scene units) from ``point`` to the closest triangle of any object."""
    from trimesh.triangles import closest_point

    point = np.asarray(point, dtype=np.float64)
    best = math.inf
    for obj in scene.objects:
        triangles = obj.mesh.vertices[obj.mesh.faces]
        nearest = closest_point(triangles, np.broadcast_to(point, (len(triangles), 3)))
        best = min(best, float(np.linalg.norm(nearest - point, axis=1).min()))
    return best


def _emitter_radius(light, scene: Scene, size: float, index_field: str) -> tuple[float, float]:
    distance = nearest_surface_distance(scene, light.position)
    if not distance > 0:
        raise InputError("a delta light on a surface cannot be replaced by an emitter of "
                         "finite size; move it off the surface", file=scene.source,
                         field=index_field, value=light.position.tolist())
    return size * distance, distance


def _sphere_emitter(center, radius: float, intensity) -> dict:
    radiance = np.asarray(intensity, dtype=np.float64) / (math.pi * radius**2)
    return {"type": "sphere", "center": [float(c) for c in center], "radius": float(radius),
            "emitter": {"type": "area", "radiance": {"type": "rgb",
                                                     "value": radiance.tolist()}}}


def point_light_equivalent(light: PointLight, scene: Scene, size: float = DEFAULT_SIZE,
                           frame_scale: float = 1.0):
    """Build a sphere emitter with the point light's intensity and power (module docstring).

    Returns
    -------
    entries : dict
        ``{"emitter": Mitsuba sphere dictionary}``.
    note : str
        One sentence for the image metadata, its lengths in units of ``scene`` divided by
        ``frame_scale`` (the user's, when ``scene`` is in a rendering frame).
    """
    radius, distance = _emitter_radius(light, scene, size, "lights.position")
    note = (f"point light -> sphere emitter of radius {radius / frame_scale:.4g} units ({size:g} "
            f"x the {distance / frame_scale:.4g} units to the nearest surface), radiance "
            f"I/(pi r^2): same "
            f"intensity and power")
    return {"emitter": _sphere_emitter(light.position, radius, light.intensity)}, note


def shade_mesh(center, axis, radius: float, opening_degrees: float,
               rings: int = 24, segments: int = 48) -> Mesh:
    """Build a spherical shell of ``radius`` about ``center`` with a round opening about ``axis``.

    The opening has half-angle ``opening_degrees``; normals point outwards.
    """
    axis = np.asarray(axis, dtype=np.float64)
    axis = axis / np.linalg.norm(axis)
    x_axis = any_perpendicular(axis)
    y_axis = np.cross(axis, x_axis)
    theta0 = math.radians(opening_degrees)
    thetas = theta0 + (math.pi - theta0) * np.arange(rings) / rings
    phis = 2.0 * math.pi * np.arange(segments) / segments
    theta, phi = np.meshgrid(thetas, phis, indexing="ij")
    local = np.stack([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi),
                      np.cos(theta)], axis=-1).reshape(-1, 3)
    local = np.vstack([local, [0.0, 0.0, -1.0]])  # the pole opposite the opening
    directions = local @ np.stack([x_axis, y_axis, axis])
    faces = []
    for ring in range(rings - 1):
        for seg in range(segments):
            a = ring * segments + seg
            b = ring * segments + (seg + 1) % segments
            faces += [[a, a + segments, b], [b, a + segments, b + segments]]
    pole = rings * segments
    last = (rings - 1) * segments
    faces += [[last + seg, pole, last + (seg + 1) % segments] for seg in range(segments)]
    return Mesh(np.asarray(center) + radius * directions, np.array(faces), directions,
                name="spot light shade")


def spot_light_equivalent(light: SpotLight, scene: Scene, size: float = DEFAULT_SIZE,
                          frame_scale: float = 1.0):
    """Build a sphere emitter in a black shade with the spot's cone and fall-off (module docstring).

    Returns
    -------
    entries : dict
        ``{"emitter": Mitsuba sphere dictionary, "shade": (Mesh, BSDF dictionary)}``.
    note : str
        One sentence for the image metadata (lengths as :func:`point_light_equivalent`'s).
    """
    radius, distance = _emitter_radius(light, scene, size, "lights.position")
    falloff = max(light.cutoff_angle - light.beam_width,
                  MIN_SPOT_FALLOFF_FRACTION * light.cutoff_angle)
    half_band = math.sin(math.radians(falloff / 2.0))
    radius = min(radius, SHADE_FRACTION * distance * half_band)
    shade_radius = radius / half_band
    opening = light.cutoff_angle - falloff / 2.0
    shade = shade_mesh(light.position, light.direction, shade_radius, opening)
    black = {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.0, 0.0, 0.0]}}
    note = (f"spot light -> sphere emitter of radius {radius / frame_scale:.4g} units, radiance "
            f"I/(pi r^2), in a black shade of radius {shade_radius / frame_scale:.4g} units open "
            f"over {opening:.4g} "
            f"degrees (fall-off over {falloff:.3g} degrees, S-shaped not linear)")
    return {"emitter": _sphere_emitter(light.position, radius, light.intensity),
            "shade": (shade, black)}, note


def lat_long_directions(height: int, width: int) -> tuple[np.ndarray, np.ndarray]:
    r"""Return the texel-centre directions of Mitsuba's ``envmap`` and their solid angles.

    Mitsuba looks a direction :math:`d` up at :math:`u = \mathrm{atan2}(d_x, -d_z)/2\pi`,
    :math:`v = \arccos(d_y)/\pi` and interpolates bilinearly between texel centres at
    :math:`u = (j + 1/2)/W` and :math:`v = i/(H - 1)` (measured with ``emitter.eval``).

    Returns
    -------
    directions : ndarray, shape (H, W, 3)
    solid_angles : ndarray, shape (H, W)
        sr per texel (the trapezoid weights of that interpolation; 0 on the pole rows).
    """
    theta = math.pi * np.arange(height) / (height - 1)
    phi = 2.0 * math.pi * (np.arange(width) + 0.5) / width
    theta, phi = np.meshgrid(theta, phi, indexing="ij")
    directions = np.stack([np.sin(phi) * np.sin(theta), np.cos(theta),
                           -np.cos(phi) * np.sin(theta)], axis=-1)
    solid_angles = (2.0 * math.pi / width) * (math.pi / (height - 1)) * np.sin(theta)
    return directions, solid_angles


def _disk_coverage(height: int, width: int, sun: np.ndarray, alpha: float,
                   subsamples: int = 4) -> np.ndarray:
    """Fraction of each texel's cell whose directions lie within ``alpha`` of ``sun``."""
    offsets = (np.arange(subsamples) + 0.5) / subsamples
    coverage = np.zeros((height, width))
    cos_alpha = math.cos(alpha)
    for du in offsets:
        for dv in offsets - 0.5:
            theta = math.pi * np.clip(np.arange(height) + dv, 0, height - 1) / (height - 1)
            phi = 2.0 * math.pi * (np.arange(width) + du) / width
            theta_grid, phi_grid = np.meshgrid(theta, phi, indexing="ij")
            cosine = (np.sin(phi_grid) * np.sin(theta_grid) * sun[0]
                      + np.cos(theta_grid) * sun[1]
                      - np.cos(phi_grid) * np.sin(theta_grid) * sun[2])
            coverage += cosine >= cos_alpha
    return coverage / subsamples**2


@dataclass
class EnvironmentParts:
    """Everything that ends up in the one environment emitter Mitsuba allows.

    Constant radiance, image environments (scaled) and stand-in suns are summed into a
    ``constant`` emitter when only constants are present, else into one ``envmap``.
    """

    constant: np.ndarray = field(default_factory=lambda: np.zeros(3))
    has_constant: bool = False
    images: list = field(default_factory=list)
    suns: list = field(default_factory=list)

    def add_constant(self, radiance) -> None:
        """Add uniform radiance (W sr^-1 m^-2, RGB)."""
        self.constant = self.constant + np.asarray(radiance, dtype=np.float64)
        self.has_constant = True

    def add_image(self, light: ImageEnvironment) -> None:
        """Add an image environment (its ``scale`` applied)."""
        if self.images and self.images[0].shape != light.radiance.shape:
            raise InputError(f"all image environments must share one resolution "
                             f"{self.images[0].shape}", field="lights.radiance",
                             value=light.radiance.shape)
        self.images.append(light.radiance.astype(np.float64) * light.scale)

    def add_sun(self, light: DirectionalLight, size: float = DEFAULT_SIZE) -> str:
        """Add a disk of angular radius ``arcsin(size)`` for a directional light; say what."""
        alpha = math.asin(size)
        self.suns.append((-light.direction, alpha, np.asarray(light.irradiance, np.float64)))
        return (f"directional light -> environment disk of angular radius "
                f"{math.degrees(alpha):.3g} degrees with the same irradiance facing it")

    def _resolution(self) -> tuple[int, int]:
        if self.images:
            return self.images[0].shape[:2]
        alpha = min(alpha for _, alpha, _ in self.suns)
        width = 2 * math.ceil(SUN_TEXELS_PER_DIAMETER * math.pi / (2.0 * alpha))
        return max(width // 2, 8), max(width, 16)

    def radiance_map(self) -> np.ndarray:
        """Return the summed latitude-longitude radiance map, float32 (H, W, 3)."""
        height, width = self._resolution()
        radiance = np.zeros((height, width, 3)) + self.constant
        for image in self.images:
            radiance += image
        directions, solid_angles = lat_long_directions(height, width)
        for sun, alpha, irradiance in self.suns:
            coverage = _disk_coverage(height, width, sun, alpha)
            cosine = np.clip(directions @ sun, 0.0, None)
            # normalise on the grid Mitsuba interpolates, so the facing irradiance is exact
            weight = float((coverage * cosine * solid_angles).sum())
            radiance += coverage[..., None] * (irradiance / weight)
        return radiance.astype(np.float32)

    def mitsuba_entry(self) -> dict | None:
        """Return the ``constant`` or ``envmap`` dictionary (None: no environment)."""
        if not self.images and not self.suns:
            if not self.has_constant:
                return None
            return {"type": "constant",
                    "radiance": {"type": "rgb", "value": self.constant.tolist()}}
        from ..backend import mitsuba

        return {"type": "envmap", "bitmap": mitsuba().Bitmap(self.radiance_map())}
