"""MuJoCo's OpenGL backend: an offscreen renderer, or one clear error line.

MuJoCo picks its backend from ``MUJOCO_GL`` when ``mujoco`` is first imported; with
``osmesa`` and no libOSMesa that import itself fails. Nothing here imports MuJoCo at
module level, so the failure can be reported instead of raised from an import.
"""

import copy
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


def open_renderer(model, width: int, height: int):
    """A ``mujoco.Renderer`` of ``width x height`` for a copy of ``model`` (its offscreen
    buffer enlarged as needed), or ``RenderError``."""
    mujoco = import_mujoco()
    model = copy.copy(model)
    model.vis.global_.offwidth = max(model.vis.global_.offwidth, width)
    model.vis.global_.offheight = max(model.vis.global_.offheight, height)
    with warnings.catch_warnings(record=True) as caught:  # GLFW warns, then MuJoCo fails
        warnings.simplefilter("always")
        try:
            return mujoco.Renderer(model, height=height, width=width)
        except Exception as err:  # ImportError, mujoco.FatalError, AttributeError
            raise render_error(err, notes=[str(w.message) for w in caught][:1]) from None
