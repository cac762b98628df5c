"""The multibody force laws: one module per law (or family of laws), each registering its
laws with :func:`..force_law.register_law` (see :mod:`..force_law`)."""
