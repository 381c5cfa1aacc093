"""The one GL context factory: a standalone, headless EGL context through moderngl.

Everything that renders (``axdf run --render``, ``axdf render``, the benchmark, the tests)
gets its context from :func:`create_gl_context`. The context is created lazily, inside the
process that renders: never create one before worker processes fork (a GL context does not
survive ``fork``). :func:`create_gl_context` records the creating process id and
:func:`check_same_process` refuses a context inherited across a fork.

The EGL and GL libraries and the device are chosen by explicit arguments only. glcontext's
own environment variables (``GLCONTEXT_LINUX_LIBEGL``, ``GLCONTEXT_DEVICE_INDEX`` ...) are
bypassed on purpose: the backend is called directly with the resolved arguments, so nothing
in the environment quietly switches the renderer.

- On a machine without a GPU this is Mesa's llvmpipe (software rasterizer).
- With NVIDIA's EGL, ``device`` picks the GPU by EGL device index (EGL_EXT_device_enumeration).

No usable EGL raises :class:`EnvironmentProblem` (exit 3) with the apt-get command.
"""
from __future__ import annotations

import os
from ctypes.util import find_library
from dataclasses import dataclass

from axdf_cli.errors import EnvironmentProblem

EGL_HINT = ("install Mesa's EGL: apt-get install -y libegl1 libegl-mesa0 libgl1-mesa-dri libgles2 "
            "(or `make sysdeps` as root)")

# OpenGL 3.3 core is all the renderer needs (MRT, integer-exact float attachments, VAOs).
GL_REQUIRE = 330


@dataclass(frozen=True)
class GLInfo:
    renderer: str  # GL_RENDERER, e.g. "llvmpipe (LLVM 15.0.6, 256 bits)"
    version: str  # GL_VERSION, e.g. "4.5 (Core Profile) Mesa 22.3.6"
    vendor: str  # GL_VENDOR


def create_gl_context(device: int | None = None, libegl: str | None = None, libgl: str | None = None):
    """Create a standalone EGL OpenGL (>= 3.3 core) context.

    ``device``: EGL device index (None: the first device). ``libegl`` / ``libgl``: library
    file names or paths (None: found with ``ctypes.util.find_library``). Returns a
    ``moderngl.Context``; raises :class:`EnvironmentProblem` when EGL is not usable.
    """
    try:
        import moderngl
        from glcontext import egl
    except ImportError as e:
        raise EnvironmentProblem(f"cannot import the GL bindings ({e})",
                                 "pip install 'moderngl>=5.8' (make setup does this)") from None
    libegl = libegl or find_library("EGL")
    libgl = libgl or find_library("GL")
    if libegl is None:
        raise EnvironmentProblem("no EGL library (libEGL.so.1) found", EGL_HINT)
    if libgl is None:
        raise EnvironmentProblem("no OpenGL library (libGL.so.1) found", EGL_HINT)
    kwargs = {"glversion": GL_REQUIRE, "mode": "standalone", "libegl": libegl, "libgl": libgl}
    if device is not None:
        kwargs["device_index"] = int(device)
    try:
        backend = egl.create_context(**kwargs)
    except Exception as e:  # glcontext raises plain Exception for every EGL failure
        raise EnvironmentProblem(f"cannot create an EGL context ({e})", EGL_HINT) from None
    try:
        ctx = moderngl.create_context(require=GL_REQUIRE, standalone=True, context=backend)
    except Exception as e:  # moderngl raises plain Exception / ValueError on a too-old GL
        raise EnvironmentProblem(f"cannot create an OpenGL {GL_REQUIRE // 100}.{GL_REQUIRE // 10 % 10} "
                                 f"context through EGL ({e})", EGL_HINT) from None
    ctx.extra = {"pid": os.getpid()}
    return ctx


def check_same_process(ctx) -> None:
    """Refuse a context created in another process (inherited across fork)."""
    pid = (ctx.extra or {}).get("pid")
    if pid is not None and pid != os.getpid():
        raise RuntimeError("GL context used after fork; create it inside the worker process")


def gl_info(ctx) -> GLInfo:
    info = ctx.info
    return GLInfo(renderer=str(info["GL_RENDERER"]), version=str(info["GL_VERSION"]),
                  vendor=str(info["GL_VENDOR"]))
