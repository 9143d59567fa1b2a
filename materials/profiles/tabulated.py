r"""A profile given as a table of radii and values (also read from a CSV file)."""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np

from ...errors import InputError, check_finite
from .base import RadialProfile, check_profile_values, radial_cumulative_integral

__all__ = ["TabulatedProfile"]


class TabulatedProfile(RadialProfile):
    """A user table: radii and values, linear in between, 0 beyond the last radius.

    Parameters
    ----------
    radius : array_like, shape (K,)
        Strictly increasing radii in mm, the first 0, K >= 2.
    reflection : array_like, shape (K,) or (K, 3)
        mm^-2, finite, >= 0 (one column is used for all three channels).
    transmission : array_like, optional
        Same shape, for thin sheets.
    name : str, optional
    file : path, optional
        Where the table came from (error messages).

    Raises
    ------
    InputError
        Non-increasing radii, a first radius other than 0, a shape mismatch, or NaN / Inf /
        negative values (the message names the first bad entry).
    """

    model = "table"
    summary = "a user table of radii and values, linear in between"

    def __init__(self, radius, reflection, transmission=None, *, name: str = "", file=None):
        radius = check_finite(radius, "radius", file=file)
        if radius.ndim != 1 or len(radius) < 2:
            raise InputError("must be a 1D array of at least 2 radii (mm)", file=file,
                             field="radius", value=radius.shape)
        if radius[0] != 0:
            raise InputError("the first radius must be 0 mm (the profile at the point of "
                             "incidence)", file=file, field="radius", value=float(radius[0]))
        if (np.diff(radius) <= 0).any():
            index = int(np.flatnonzero(np.diff(radius) <= 0)[0]) + 1
            raise InputError(f"radii must increase strictly (entry {index} does not)",
                             file=file, field="radius", value=float(radius[index]))
        self.radius = radius
        self.name = name or (Path(file).stem if file else "table")
        self.values = {"reflection": self._column(reflection, "reflection", file)}
        self.has_transmission = transmission is not None
        if transmission is not None:
            self.values["transmission"] = self._column(transmission, "transmission", file)

    def _column(self, values, field, file):
        values = check_profile_values(values, field, file=file, name=self.name)
        if values.ndim == 1:
            values = np.repeat(values[:, None], 3, axis=1)
        if values.shape != (len(self.radius), 3):
            raise InputError(f"must have shape ({len(self.radius)},) or ({len(self.radius)}, 3)"
                             " to match the radii", file=file, field=field, value=values.shape)
        return values

    def _interpolate(self, r, values):
        r = np.asarray(r, dtype=np.float64)
        out = np.stack([np.interp(r, self.radius, values[:, c], right=0.0) for c in range(3)],
                       axis=-1)
        return out

    def reflection(self, r) -> np.ndarray:
        """Linear interpolation of the table, mm^-2; 0 beyond the last radius."""
        return self._interpolate(r, self.values["reflection"])

    def transmission(self, r) -> np.ndarray:
        """Linear interpolation of the transmission table (0 when there is none)."""
        if not self.has_transmission:
            return super().transmission(r)
        return self._interpolate(r, self.values["transmission"])

    def support_radius(self, energy_fraction: float = 1e-3) -> float:
        """At most the table's last radius (the profile is 0 beyond)."""
        return min(super().support_radius(energy_fraction), float(self.radius[-1]))

    def total(self, kind: str = "reflection", max_radius: float | None = None) -> np.ndarray:
        """Exact for the piecewise-linear table (:func:`radial_cumulative_integral`)."""
        if max_radius is None:
            if kind == "transmission" and not self.has_transmission:
                return np.zeros(3)
            return 2.0 * np.pi * radial_cumulative_integral(self.radius, self.values[kind])[-1]
        return super().total(kind, max_radius)

    def length_scale(self) -> np.ndarray:
        """Return the table's last radius, mm (the sampling tables span six decades below)."""
        return np.full(3, float(self.radius[-1]))

    def cutoff_radius(self) -> np.ndarray:
        """Return the table's last radius, mm: the profile is 0 beyond."""
        return np.full(3, float(self.radius[-1]))

    @classmethod
    def from_file(cls, path, *, name: str = "") -> TabulatedProfile:
        """Read a CSV table of radii and profile values.

        Columns: ``r`` (mm), then 1 or 3 reflection columns, then optionally as many
        transmission columns; a header row (non-numeric) is skipped.

        Raises
        ------
        InputError
            Missing file, unreadable numbers, wrong column count, or bad values.
        """
        path = Path(path)
        if not path.is_file():
            raise InputError("no such file", file=path, field="path", value=str(path))
        rows = []
        try:
            with open(path, newline="", encoding="utf-8") as handle:
                for number, row in enumerate(csv.reader(handle), start=1):
                    cells = [cell.strip() for cell in row if cell.strip()]
                    if not cells or cells[0].startswith("#"):
                        continue
                    try:
                        rows.append([float(cell) for cell in cells])
                    except ValueError as error:
                        if rows:  # only the first row may be a header
                            raise InputError("not a number", file=path,
                                             field=f"line {number}", value=row) from error
        except (UnicodeDecodeError, csv.Error) as error:
            raise InputError(f"not a text (UTF-8) CSV file ({error})", file=path,
                             field="path", value=str(path)) from error
        if not rows:
            raise InputError("no numeric rows", file=path, field="rows", value=0)
        widths = {len(row) for row in rows}
        if len(widths) != 1 or widths.pop() not in (2, 3, 4, 7):
            raise InputError("every row needs r then 1 or 3 reflection columns, optionally "
                             "followed by as many transmission columns (2, 3, 4 or 7 numbers)",
                             file=path, field="columns", value=sorted({len(r) for r in rows}))
        table = np.array(rows)
        width = table.shape[1]
        channels = 3 if width in (4, 7) else 1
        reflection = table[:, 1:1 + channels]
        transmission = table[:, 1 + channels:] if width in (3, 7) else None
        squeeze = (lambda a: a[:, 0]) if channels == 1 else (lambda a: a)
        return cls(table[:, 0], squeeze(reflection),
                   None if transmission is None else squeeze(transmission),
                   name=name or path.stem, file=path)

    def cache_key(self) -> dict:
        """Return what identifies this profile in content hashes."""
        return {"type": "table", "radius": self.radius,
                **{kind: values for kind, values in self.values.items()}}
