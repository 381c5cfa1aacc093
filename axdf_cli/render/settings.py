"""Render settings: the job file's ``render:`` mapping and the command-line overrides.

Keys of ``render:`` (all optional; unknown keys are errors with their position):

==============  ===========================================  =================================
key             value                                        default
==============  ===========================================  =================================
enabled         true / false                                 true when ``render:`` is given
size            [W, H] output pixels (per panel for sheet)   [640, 480]
view            auto | front | side | top | sheet            auto (three-quarter front view)
fov             vertical field of view of named views, deg    30
camera          {position, target, up, fov}: explicit camera  none (automatic framing)
orbit           turntable degrees per frame about world +Z   0 (off)
wireframe       true / false: edge overlay                   false
background      [r, g, b] or [r, g, b, a] linear, or         [0.8, 0.8, 0.8, 1]
                ``transparent``
bones           true / false: draw bone meshes               true
supersample     1..8: render s times larger, box-downsample  3
device          ``default`` or an EGL device index           default
==============  ===========================================  =================================

``camera`` and ``view`` exclude each other. In ``camera``: ``position`` and ``target`` are
world points (metres), ``up`` defaults to [0, 0, 1], ``fov`` (vertical degrees) to 30.
"""
from __future__ import annotations

import argparse
import re
from dataclasses import dataclass, replace

from axdf_cli.errors import InputError, Mark, UsageError
from axdf_cli.yamlio import Fields, YMap, check_number

VIEWS = ("auto", "front", "side", "top", "sheet")
MAX_SIZE = 8192
MAX_SUPERSAMPLE = 8


@dataclass(frozen=True)
class CameraSpec:
    position: tuple[float, float, float]
    target: tuple[float, float, float]
    up: tuple[float, float, float] = (0.0, 0.0, 1.0)
    fov: float = 30.0  # vertical, degrees


@dataclass(frozen=True)
class RenderSettings:
    enabled: bool = False
    size: tuple[int, int] = (640, 480)  # (W, H) output pixels of one view
    view: str = "auto"
    fov: float = 30.0  # vertical degrees for the named views
    camera: CameraSpec | None = None
    orbit: float = 0.0  # degrees per frame about world +Z through the target
    wireframe: bool = False
    background: tuple[float, float, float, float] = (0.8, 0.8, 0.8, 1.0)  # linear RGBA
    bones: bool = True
    supersample: int = 3
    device: int | None = None  # EGL device index; None = default
    egl_library: str | None = None  # command line only (--egl-library); None = find libEGL

    @property
    def transparent(self) -> bool:
        return self.background[3] < 1.0


def parse_render_settings(value: YMap | None, where: Mark) -> RenderSettings:
    """Read the job file's ``render:`` mapping (None: rendering off, defaults)."""
    if value is None:
        return RenderSettings()
    f = Fields(value, where, "render")
    d = RenderSettings()
    enabled = f.boolean("enabled", default=True)
    size = d.size
    if f.has("size"):
        v = f.vector("size", n=2, lo=16, hi=MAX_SIZE)
        size = _int_pair(v, f.vmark("size"), "size")
    view = f.choice("view", VIEWS, default=d.view)
    fov = float(f.number("fov", default=d.fov, lo=1, hi=170))
    camera = None
    cam_map = f.mapping("camera")
    if cam_map is not None:
        if "view" in value:
            raise InputError(f.kmark("camera"), "both 'camera' and 'view' are given",
                             "give an explicit camera or a named view, not both")
        camera = _parse_camera(cam_map, f.vmark("camera"))
    orbit = float(f.number("orbit", default=d.orbit, lo=-360, hi=360))
    wireframe = f.boolean("wireframe", default=d.wireframe)
    background = d.background
    if f.has("background"):
        background = _parse_background(f.raw("background"), f.vmark("background"))
    bones = f.boolean("bones", default=d.bones)
    supersample = int(f.number("supersample", default=d.supersample, lo=1, hi=MAX_SUPERSAMPLE,
                               integer=True))
    device = None
    if f.has("device"):
        raw = f.raw("device")
        if raw != "default":
            if isinstance(raw, str):
                raise InputError(f.vmark("device"), f"device is the string {raw!r}",
                                 "device is 'default' or an EGL device index (0, 1, ...)")
            device = int(check_number(raw, f.vmark("device"), "device", lo=0, hi=255, integer=True))
    f.done()
    return RenderSettings(enabled=enabled, size=size, view=view, fov=fov, camera=camera, orbit=orbit,
                          wireframe=wireframe, background=background, bones=bones,
                          supersample=supersample, device=device)


def _int_pair(v, where: Mark, what: str) -> tuple[int, int]:
    if not all(float(x).is_integer() for x in v):
        raise InputError(where, f"{what} is {list(v)}", f"{what} is two whole numbers [W, H]")
    return int(v[0]), int(v[1])


def _parse_camera(value, where: Mark) -> CameraSpec:
    f = Fields(value, where, "camera")
    position = f.vector("position", n=3, required=True)
    target = f.vector("target", n=3, required=True)
    up = f.vector("up", n=3, default=(0.0, 0.0, 1.0))
    fov = float(f.number("fov", default=30.0, lo=1, hi=170))
    f.done()
    d = [p - t for p, t in zip(position, target)]
    if sum(x * x for x in d) < 1e-12:
        raise InputError(f.vmark("position"), "camera position equals its target",
                         "put the camera away from the target")
    cross = (d[1] * up[2] - d[2] * up[1], d[2] * up[0] - d[0] * up[2], d[0] * up[1] - d[1] * up[0])
    if sum(x * x for x in cross) < 1e-12 * max(sum(x * x for x in d), 1e-12):
        raise InputError(f.vmark("up") if f.has("up") else f.vmark("position"),
                         "camera up is parallel to the viewing direction",
                         "give an up vector not parallel to target - position")
    return CameraSpec(position=position, target=target, up=up, fov=fov)


def _parse_background(raw, where: Mark) -> tuple[float, float, float, float]:
    if raw == "transparent":
        return (0.0, 0.0, 0.0, 0.0)
    allowed = "background is [r, g, b], [r, g, b, a] (linear, 0..1) or 'transparent'"
    if not isinstance(raw, list) or len(raw) not in (3, 4):
        raise InputError(where, "background is not a colour", allowed)
    marks = getattr(raw, "item_marks", None) or [where] * len(raw)
    vals = [float(check_number(x, m, "background", lo=0, hi=1)) for x, m in zip(raw, marks)]
    if len(vals) == 3:
        vals.append(1.0)
    return tuple(vals)


# ----------------------------------------------------------------------------- command line

def add_render_args(parser: argparse.ArgumentParser) -> None:
    """Render flags shared by ``axdf run`` and ``axdf render``; all default to 'not given'."""
    g = parser.add_argument_group("rendering")
    g.add_argument("--size", metavar="WxH", help="output size in pixels per view, e.g. 512x512")
    g.add_argument("--view", choices=VIEWS, help="named view (auto = three-quarter front)")
    g.add_argument("--fov", type=float, metavar="DEG", help="vertical field of view of named views")
    g.add_argument("--orbit", type=float, metavar="DEG", help="turntable: degrees per frame about +Z")
    g.add_argument("--wireframe", action=argparse.BooleanOptionalAction, default=None,
                   help="edge overlay")
    g.add_argument("--bones", action=argparse.BooleanOptionalAction, default=None,
                   help="draw bone meshes")
    g.add_argument("--background", metavar="R,G,B[,A]|transparent",
                   help="background colour (linear 0..1) or 'transparent'")
    g.add_argument("--supersample", type=int, metavar="N", help="anti-aliasing factor 1..8")
    g.add_argument("--device", metavar="default|N", help="EGL device index")
    g.add_argument("--egl-library", metavar="PATH",
                   help="EGL library to load instead of the system's libEGL.so.1 (diagnosis)")


_SIZE_RE = re.compile(r"^(\d+)[xX](\d+)$")


def settings_from_args(settings: RenderSettings, args: argparse.Namespace) -> RenderSettings:
    """Apply the flags of :func:`add_render_args` that were given; raise UsageError on bad ones."""
    s = settings
    if getattr(args, "size", None) is not None:
        m = _SIZE_RE.match(args.size)
        if not m:
            raise UsageError(f"--size {args.size!r} is not WxH", "e.g. --size 512x512")
        w, h = int(m.group(1)), int(m.group(2))
        if not (16 <= w <= MAX_SIZE and 16 <= h <= MAX_SIZE):
            raise UsageError(f"--size {args.size} is out of range", f"16..{MAX_SIZE} pixels each way")
        s = replace(s, size=(w, h))
    if getattr(args, "view", None) is not None:
        s = replace(s, view=args.view, camera=None)
    if getattr(args, "fov", None) is not None:
        if not 1 <= args.fov <= 170:
            raise UsageError(f"--fov {args.fov:g} is out of range", "1..170 degrees")
        s = replace(s, fov=float(args.fov))
    if getattr(args, "orbit", None) is not None:
        if not -360 <= args.orbit <= 360:
            raise UsageError(f"--orbit {args.orbit:g} is out of range", "-360..360 degrees per frame")
        s = replace(s, orbit=float(args.orbit))
    if getattr(args, "wireframe", None) is not None:
        s = replace(s, wireframe=bool(args.wireframe))
    if getattr(args, "bones", None) is not None:
        s = replace(s, bones=bool(args.bones))
    if getattr(args, "background", None) is not None:
        s = replace(s, background=_background_flag(args.background))
    if getattr(args, "supersample", None) is not None:
        if not 1 <= args.supersample <= MAX_SUPERSAMPLE:
            raise UsageError(f"--supersample {args.supersample} is out of range", f"1..{MAX_SUPERSAMPLE}")
        s = replace(s, supersample=int(args.supersample))
    if getattr(args, "device", None) is not None:
        if args.device == "default":
            s = replace(s, device=None)
        elif args.device.isdigit():
            s = replace(s, device=int(args.device))
        else:
            raise UsageError(f"--device {args.device!r}", "--device is 'default' or an EGL device index")
    if getattr(args, "egl_library", None) is not None:
        s = replace(s, egl_library=args.egl_library)
    return s


def _background_flag(text: str) -> tuple[float, float, float, float]:
    if text == "transparent":
        return (0.0, 0.0, 0.0, 0.0)
    try:
        vals = [float(x) for x in text.split(",")]
    except ValueError:
        vals = []
    if len(vals) not in (3, 4) or not all(0.0 <= v <= 1.0 for v in vals):
        raise UsageError(f"--background {text!r}", "R,G,B or R,G,B,A with values 0..1, or 'transparent'")
    if len(vals) == 3:
        vals.append(1.0)
    return tuple(vals)


def settings_to_dict(s: RenderSettings) -> dict:
    """The settings as the job file's ``render:`` mapping (for the manifest; re-read by
    :func:`parse_render_settings`). The EGL device and library are machine choices: omitted."""
    d = {"enabled": s.enabled, "size": list(s.size), "fov": s.fov, "orbit": s.orbit,
         "wireframe": s.wireframe, "background": list(s.background), "bones": s.bones,
         "supersample": s.supersample}
    if s.camera is not None:
        d["camera"] = {"position": list(s.camera.position), "target": list(s.camera.target),
                       "up": list(s.camera.up), "fov": s.camera.fov}
    else:
        d["view"] = s.view
    return d
