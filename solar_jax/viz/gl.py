"""MuJoCo's OpenGL backend: an offscreen renderer, or one clear error line.

MuJoCo picks its backend from ``MUJOCO_GL`` when ``mujoco`` is first imported; with
``osmesa`` and no libOSMesa that import itself fails. The package imports MuJoCo with
the backend disabled (``solar_jax/__init__.py``: training never renders), so the
renderer here opens the ``MUJOCO_GL`` backend itself, when a video asks for one, and a
failure is one error line. Nothing here imports MuJoCo at module level.
"""

import copy
import importlib
import os
import warnings

FIX = (
    "install libEGL (or OSMesa) and set MUJOCO_GL=egl (or MUJOCO_GL=osmesa) before "
    "mujoco is first imported"
)


class RenderError(RuntimeError):
    """No OpenGL context: MuJoCo cannot render here."""


def render_error(err: BaseException, what: str = "cannot render", notes=()) -> RenderError:
    """One line: what failed, the backend tried, the underlying error, and the fix."""
    backend = os.environ.get("MUJOCO_GL") or "glfw (MUJOCO_GL unset)"
    first = (str(err).strip().splitlines() or [""])[0]
    why = "; ".join([f"{type(err).__name__}: {first}", *notes])
    return RenderError(f"{what}: no OpenGL context with MUJOCO_GL={backend} ({why}); {FIX}")


def import_mujoco():
    """``mujoco``, or ``RenderError`` when importing it fails on its OpenGL backend."""
    try:
        import mujoco
    except Exception as err:  # AttributeError from PyOpenGL, RuntimeError on a bad value
        raise render_error(err, "cannot import mujoco") from None
    return mujoco


BACKENDS = {"egl": "mujoco.egl", "osmesa": "mujoco.osmesa", "glfw": "mujoco.glfw"}
DISABLED = ("disable", "disabled", "off", "false", "0")


def ensure_gl_context() -> None:
    """Gives MuJoCo's renderer the ``MUJOCO_GL`` backend (unset: glfw) where it has none
    because MuJoCo was imported with OpenGL disabled; ``RenderError`` when it cannot."""
    from mujoco.rendering.classic import gl_context

    if getattr(gl_context, "GLContext", None) is not None:
        return
    backend = os.environ.get("MUJOCO_GL", "").lower().strip() or "glfw"
    if backend in DISABLED:
        raise render_error(RuntimeError("rendering is disabled"))
    if backend not in BACKENDS:
        valid = ", ".join(BACKENDS)
        raise render_error(ValueError(f"unknown backend {backend!r}; valid: {valid}"))
    try:
        module = importlib.import_module(BACKENDS[backend])
    except Exception as err:  # AttributeError from PyOpenGL without the library
        raise render_error(err) from None
    gl_context.GLContext = module.GLContext


def open_renderer(model, width: int, height: int):
    """A ``mujoco.Renderer`` of ``width x height`` for a copy of ``model`` (its offscreen
    buffer enlarged as needed), or ``RenderError``."""
    mujoco = import_mujoco()
    ensure_gl_context()
    model = copy.copy(model)
    model.vis.global_.offwidth = max(model.vis.global_.offwidth, width)
    model.vis.global_.offheight = max(model.vis.global_.offheight, height)
    with warnings.catch_warnings(record=True) as caught:  # GLFW warns, then MuJoCo fails
        warnings.simplefilter("always")
        try:
            return mujoco.Renderer(model, height=height, width=width)
        except Exception as err:  # ImportError, mujoco.FatalError, AttributeError
            raise render_error(err, notes=[str(w.message) for w in caught][:1]) from None
