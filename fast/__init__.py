"""The approximations, one module each: prt, radiosity, splatting, brdf_pca.

Nothing here imports :mod:`translucent.reference`: an approximation must not quietly call
the path tracer.
"""
