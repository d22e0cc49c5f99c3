"""Guards for tests: nothing retraces where nothing should, and no PRNG key is reused.

>>> with no_retracing("the steady-state steps"):
...     state, _ = step(state, actions)  # fails if step meets a new shape or static value
"""

import contextlib

import jax

TRACE_EVENT = "/jax/core/compile/jaxpr_trace_duration"  # JAX records one per trace


@contextlib.contextmanager
def no_retracing(what: str):
    """Fails if any jitted function is traced inside the block: a shape, a dtype or a static
    value changed since its last call (or it was never called before). Yields the list of
    what was traced so far."""
    traced = []

    def listener(event: str, duration: float, **kwargs):
        if event == TRACE_EVENT:
            traced.append(kwargs.get("fun_name", "?"))

    jax.monitoring.register_event_duration_secs_listener(listener)
    try:
        yield traced
    finally:
        jax.monitoring.unregister_event_duration_listener(listener)
    assert not traced, f"{what} traced again: {', '.join(traced)}"


@contextlib.contextmanager
def key_reuse_checked():
    """JAX's key-reuse checker on (``jax_debug_key_reuse``): a typed key
    (``jax.random.key``) consumed twice inside the block raises ``KeyReuseError``."""
    with jax.debug_key_reuse(True):
        yield


def check_keys_used_once(fun, *args) -> None:
    """Traces ``fun(*args)`` (no compile) with JAX's key-reuse checker on: raises
    ``KeyReuseError`` if a typed key among ``args`` (``jax.random.key``), or one split
    from it, is consumed twice."""
    with key_reuse_checked():
        jax.eval_shape(jax.jit(fun), *args)
