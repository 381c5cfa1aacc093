"""Headless preview rendering (EGL + moderngl): PNG previews, OpenEXR data passes, camera.json.

Public API: :func:`render_sequence`, :func:`parse_render_settings`, :class:`RenderSettings`,
:func:`add_render_args`, :func:`settings_from_args`, :func:`load_run_scene`,
:func:`benchmark_fps`, :func:`create_gl_context`. Heavy modules (moderngl, OpenEXR) are
imported only when rendering starts.
"""
from axdf_cli.specs.render import (RenderSettings, CameraSpec, add_render_args,  # noqa: F401
                                      parse_render_settings, settings_from_args)


def render_sequence(*args, **kwargs):
    from axdf_cli.render.framefiles import render_sequence as f
    return f(*args, **kwargs)


def benchmark_fps(*args, **kwargs):
    from axdf_cli.render.framefiles import benchmark_fps as f
    return f(*args, **kwargs)


def load_run_scene(*args, **kwargs):
    from axdf_cli.render.runio import load_run_scene as f
    return f(*args, **kwargs)


def create_gl_context(*args, **kwargs):
    from axdf_cli.render.context import create_gl_context as f
    return f(*args, **kwargs)
