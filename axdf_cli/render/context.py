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

No usable EGL raises :class:`EnvironmentProblem` (exit 3) with the apt-get command; a
``device`` that does not exist names the devices that do (:func:`egl_devices`).
:func:`probe` creates a context only to read the renderer and its size limit (``axdf run``
calls it in a forked child before the mesh pass, so a refusal comes before any file).
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
        devices = egl_devices(libegl)
        if devices is not None and not 0 <= int(device) < len(devices):
            raise EnvironmentProblem(f"there is no EGL device {device}; this machine has {_device_list(devices)}",
                                     "pass --device with one of them, or --device default")
        kwargs["device_index"] = int(device)
    try:
        backend = egl.create_context(**kwargs)
    except Exception as e:  # glcontext raises plain Exception for every EGL failure
        if device is not None:  # EGL itself loads: say which devices there are
            devices = egl_devices(libegl)
            if devices:
                raise EnvironmentProblem(f"cannot create an EGL context on device {device} ({e}); this machine "
                                         f"has {_device_list(devices)}", "try another --device, or --device default") \
                    from None
        raise EnvironmentProblem(f"cannot create an EGL context ({e})", EGL_HINT) from None
    try:
        ctx = moderngl.create_context(require=GL_REQUIRE, standalone=True, context=backend)
    except Exception as e:  # moderngl raises plain Exception / ValueError on a too-old GL
        raise EnvironmentProblem(f"cannot create an OpenGL {GL_REQUIRE // 100}.{GL_REQUIRE // 10 % 10} "
                                 f"context through EGL ({e})", EGL_HINT) from None
    ctx.extra = {"pid": os.getpid()}
    return ctx


EGL_EXTENSIONS = 0x3055
EGL_DRM_DEVICE_FILE_EXT = 0x3233
EGL_RENDERER_EXT = 0x335F


def egl_devices(libegl: str | None = None) -> list[str] | None:
    """Names of the EGL devices (EGL_EXT_device_enumeration), index by index, or None when
    the library cannot enumerate them."""
    import ctypes

    try:
        lib = ctypes.CDLL(libegl or find_library("EGL") or "libEGL.so.1")
        gpa = lib.eglGetProcAddress
    except (OSError, AttributeError):
        return None
    gpa.restype, gpa.argtypes = ctypes.c_void_p, [ctypes.c_char_p]
    query, qstring = gpa(b"eglQueryDevicesEXT"), gpa(b"eglQueryDeviceStringEXT")
    if not query:
        return None
    query = ctypes.CFUNCTYPE(ctypes.c_uint, ctypes.c_int, ctypes.POINTER(ctypes.c_void_p),
                             ctypes.POINTER(ctypes.c_int))(query)
    n = ctypes.c_int(0)
    if not query(0, None, ctypes.byref(n)):
        return None
    devs = (ctypes.c_void_p * max(n.value, 1))()
    if not query(n.value, devs, ctypes.byref(n)):
        return None
    qstring = ctypes.CFUNCTYPE(ctypes.c_char_p, ctypes.c_void_p, ctypes.c_int)(qstring) if qstring else None
    names = []
    for d in devs[:n.value]:
        name = None
        if qstring is not None:
            ext = (qstring(d, EGL_EXTENSIONS) or b"").decode("ascii", "replace").split()
            if "EGL_EXT_device_query_name" in ext:
                name = qstring(d, EGL_RENDERER_EXT)
            if not name and "EGL_EXT_device_drm" in ext:
                name = qstring(d, EGL_DRM_DEVICE_FILE_EXT)
            if not name and "EGL_MESA_device_software" in ext:
                name = b"software rasterizer"
        names.append(name.decode("utf-8", "replace") if name else "unnamed")
    return names


def _device_list(devices: list[str]) -> str:
    if not devices:
        return "no EGL device"
    return f"{len(devices)} EGL device(s): " + ", ".join(f"{i} ({n})" for i, n in enumerate(devices))


def size_limit(ctx) -> int:
    """The largest render target side this context draws into (texture, renderbuffer, viewport)."""
    info = ctx.info
    vp = info.get("GL_MAX_VIEWPORT_DIMS", (1 << 30, 1 << 30))
    return int(min(info["GL_MAX_TEXTURE_SIZE"], info["GL_MAX_RENDERBUFFER_SIZE"], *vp))


def probe(settings) -> tuple["GLInfo", int]:
    """Create a context for ``settings`` (device, EGL library), read its renderer and
    :func:`size_limit`, release it. Raises EnvironmentProblem like :func:`create_gl_context`."""
    ctx = create_gl_context(device=settings.device, libegl=settings.egl_library)
    try:
        return gl_info(ctx), size_limit(ctx)
    finally:
        ctx.release()


def check_same_process(ctx) -> None:
    """Refuse a context created in another process (inherited across fork)."""
    pid = (ctx.extra or {}).get("pid")
    if pid is not None and pid != os.getpid():
        raise RuntimeError("GL context used after fork; create it inside the worker process")


def gl_info(ctx) -> GLInfo:
    info = ctx.info
    return GLInfo(renderer=str(info["GL_RENDERER"]), version=str(info["GL_VERSION"]),
                  vendor=str(info["GL_VENDOR"]))
