"""XLA for solar_jax: the on-disk cache and its keys (``cache``), compiler options per kind
of program (``options``), traced programs kept and compiled side by side (``programs``),
and compile times remembered per machine (``times``)."""
