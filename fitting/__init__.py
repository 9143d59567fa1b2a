"""Captured slab images -> radial profiles -> posteriors over dipole and SubEdit parameters."""
