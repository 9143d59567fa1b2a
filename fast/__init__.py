"""The approximations, one package of the same shape each: prt, radiosity, splatting, brdf_pca.

Each method's package has ``knobs``, ``method`` (the whole contract), ``state`` and its own
physics and kernels; what several methods share sits here beside them (``contract``,
``base``, ``registry``, ``conformance``, ``knobs``, ``solid_inputs``, ``sparse_transport``,
``wavelets``).

Nothing here imports :mod:`translucent.reference`: an approximation must not quietly call
the path tracer.
"""
