"""Render settings: the job file's ``render:`` mapping and the command-line overrides.

Keys of ``render:`` (all optional; unknown keys are errors with their position):

==============  ===========================================  =================================
key             value                                        default
==============  ===========================================  =================================
enabled         true / false                                 true when ``render:`` is given
size            [W, H] or ``WxH``: pixels (per panel: sheet)  [640, 480]
view            auto | front | side | top | sheet            auto (three-quarter front view)
fov             vertical field of view, degrees 1..170       30
camera          {position, target, up, fov}: explicit camera  none (automatic framing)
orbit           turntable degrees per frame about world +Z   0 (off)
wireframe       true / false: edge overlay                   false
background      [r, g, b] or [r, g, b, a] linear, or         [0.8, 0.8, 0.8, 1]
                ``transparent``
bones           true / false: draw bone meshes (sticks       true
                between joints for bones without a mesh)
supersample     1..8: render s times larger, box-downsample  3
device          ``default`` or an EGL device index           default
==============  ===========================================  =================================

``camera`` and ``view`` exclude each other. In ``camera``: ``position`` and ``target`` are
world points (metres; ``target`` defaults to the centre of the automatic framing), ``up``
defaults to [0, 0, 1], ``fov`` to the ``fov`` above. ``target`` may name a bone instead
(``bone:NAME`` or ``{bone: NAME}``): the camera aims at that bone's origin at every frame.
With a bone target, ``position`` (a fixed camera that turns to follow the bone) is
optional: ``offset: [x, y, z]`` (world axes, metres) makes a camera that moves with the bone
at that offset from it, and with neither the camera moves with the bone at the automatic
view's direction and distance (the ``auto`` view, fitted to the framing).

Every setting is read by one parser from :data:`RANGES`, for YAML values and for flags
alike: a flag's text is read as a YAML value (``--size 512x256`` or ``--size "[512, 256]"``,
``--background 0,0,1`` or ``"[0, 0, 1]"``), so both spellings work in both places and a bad
value is reported the same way (``--fov: fov is 200; fov must be in [1, 170]``).
"""
from __future__ import annotations

import argparse
import math
import re
from dataclasses import dataclass, field, replace

from axdf_cli.errors import InputError, Mark
from axdf_cli.fileio.yamlio import NAME_ALLOWED, Fields, check_number, check_vector, is_name, parse_yaml

VIEWS = ("auto", "front", "side", "top", "sheet")
#: How a run's skin (``axdf run --skin``) is drawn: over the muscles at SKIN_ALPHA (the data
#: passes see the muscles), as an opaque body (the passes see the skin), or not at all.
SKIN_VIEWS = ("see-through", "opaque", "off")

#: The one table of ranges, for the ``render:`` block and the flags: key -> (lo, hi).
RANGES = {
    "size": (16, 8192),  # pixels each way
    "fov": (1.0, 170.0),  # vertical degrees
    "orbit": (-360.0, 360.0),  # degrees per frame
    "supersample": (1, 8),
    "device": (0, 255),
    "background": (0.0, 1.0),  # linear colour channels
}
MAX_SIZE = RANGES["size"][1]
MAX_SUPERSAMPLE = RANGES["supersample"][1]
DEFAULT_FOV = 30.0


@dataclass(frozen=True)
class CameraSpec:
    position: tuple[float, float, float] | None  # None: only with a bone target (offset or automatic)
    target: tuple[float, float, float] | None = None  # None: the centre of the automatic framing
    up: tuple[float, float, float] = (0.0, 0.0, 1.0)
    fov: float = DEFAULT_FOV  # vertical, degrees
    target_bone: str | None = None  # aim at this bone's origin at every frame (target is None)
    offset: tuple[float, float, float] | None = None  # with target_bone: move with the bone at this offset
    target_mark: Mark | None = field(default=None, compare=False)  # where the bone was named (checks)

    @property
    def follows(self) -> bool:
        """The camera moves with its target bone (an offset, or no position: automatic)."""
        return self.target_bone is not None and self.position is None


@dataclass(frozen=True)
class RenderSettings:
    enabled: bool = False
    size: tuple[int, int] = (640, 480)  # (W, H) output pixels of one view
    view: str = "auto"
    fov: float = DEFAULT_FOV  # vertical degrees for the named views
    camera: CameraSpec | None = None
    orbit: float = 0.0  # degrees per frame about world +Z through the target
    wireframe: bool = False
    background: tuple[float, float, float, float] = (0.8, 0.8, 0.8, 1.0)  # linear RGBA
    bones: bool = True
    supersample: int = 3
    device: int | None = None  # EGL device index; None = default
    skin: str = "see-through"  # one of SKIN_VIEWS; only a run with a skin has one to draw
    egl_library: str | None = None  # command line only (--egl-library); None = find libEGL
    pinned: "PinnedCameras | None" = None  # command line only (--camera FILE): cameras read from a camera.json

    @property
    def transparent(self) -> bool:
        return self.background[3] < 1.0


@dataclass(frozen=True)
class PinnedView:
    """One panel's camera as a ``camera.json`` holds it (numbers as written there)."""

    view: str
    K: tuple  # 3 x 3 rows, pixels
    world_to_camera: tuple  # 4 x 4 rows
    viewport: tuple[int, int, int, int]
    near: float
    far: float


@dataclass(frozen=True)
class PinnedCameras:
    """``axdf run --camera FILE``: the cameras of an earlier run's ``camera.json``, reused as
    they are (a golden check renders through the golden's own cameras, so a change to one
    muscle moves only that muscle's pixels, never the automatic framing of the rest)."""

    source: str  # the file, as given
    sha256: str  # of its bytes (recorded in the manifest)
    width: int  # whole image (every panel), pixels
    height: int
    frames: tuple[tuple[int, tuple[PinnedView, ...]], ...]  # (frame, one camera per panel)

    @property
    def fixed(self) -> bool:
        """Every frame holds the same cameras (a fixed camera: usable for any frame)."""
        return len({views for _, views in self.frames}) == 1

    def views_for(self, frame: int) -> tuple[PinnedView, ...] | None:
        """The cameras of ``frame``: its own, or a fixed camera's; None when the file has none."""
        for f, views in self.frames:
            if f == int(frame):
                return views
        return self.frames[0][1] if self.fixed else None


def _numbers(v, shape: tuple[int, ...]) -> tuple | None:
    """``v`` as nested tuples of finite floats of ``shape``, or None."""
    if len(shape) == 0:
        ok = isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)
        return float(v) if ok else None
    if not isinstance(v, list) or len(v) != shape[0]:
        return None
    out = tuple(_numbers(x, shape[1:]) for x in v)
    return None if any(x is None for x in out) else out


def read_pinned_cameras(path: str) -> PinnedCameras:
    """A ``camera.json`` (as ``axdf run`` writes it) read for ``--camera``; anything else is an
    InputError naming the file and what is wrong."""
    import hashlib
    import json

    allowed = "a camera.json written by axdf run or axdf render (a golden run's own)"
    try:
        data = open(path, "rb").read()
    except OSError as e:
        raise InputError(Mark(path), f"cannot read the camera file ({e.strerror or e})", allowed) from None
    try:
        doc = json.loads(data)
    except (ValueError, UnicodeDecodeError) as e:
        raise InputError(Mark(path), f"is not JSON ({e})", allowed) from None
    if not isinstance(doc, dict) or not isinstance(doc.get("frames"), list) or not doc["frames"]:
        raise InputError(Mark(path), "has no 'frames' list of cameras", allowed)
    w, h = doc.get("width"), doc.get("height")
    if not all(isinstance(x, int) and not isinstance(x, bool) and x > 0 for x in (w, h)):
        raise InputError(Mark(path), "has no positive whole 'width' and 'height'", allowed)
    frames = []
    for i, fr in enumerate(doc["frames"]):
        cams = fr.get("cameras") if isinstance(fr, dict) else None
        if not isinstance(fr, dict) or not isinstance(fr.get("frame"), int) or not isinstance(cams, list) or not cams:
            raise InputError(Mark(path), f"frames[{i}] is not {{frame, cameras: [...]}}", allowed)
        views = []
        for j, c in enumerate(cams):
            c = c if isinstance(c, dict) else {}
            K, M = _numbers(c.get("K"), (3, 3)), _numbers(c.get("world_to_camera"), (4, 4))
            vp, near, far = _numbers(c.get("viewport"), (4,)), _numbers(c.get("near"), ()), _numbers(c.get("far"), ())
            if None in (K, M, vp, near, far) or not isinstance(c.get("view"), str) or not 0 < near < far:
                raise InputError(Mark(path), f"frames[{i}].cameras[{j}] is not a camera "
                                 "{view, K 3x3, world_to_camera 4x4, viewport [x, y, w, h], 0 < near < far}", allowed)
            views.append(PinnedView(c["view"], K, M, tuple(int(x) for x in vp), near, far))
        frames.append((int(fr["frame"]), tuple(views)))
    if len({len(v) for _, v in frames}) != 1:
        raise InputError(Mark(path), "its frames hold different numbers of panels", allowed)
    return PinnedCameras(str(path), hashlib.sha256(data).hexdigest(), w, h, tuple(frames))


def check_pinned(s: RenderSettings, frames) -> None:
    """A run pinned to a camera file (``--camera``) renders at that file's size and every one
    of its ``frames`` has a camera there (its own, or a fixed camera's); else an InputError."""
    p = s.pinned
    if p is None or not s.enabled:
        return
    panels = len(p.frames[0][1])
    W, H = s.size
    if (W * panels, H) != (p.width, p.height):
        raise InputError(Mark(p.source), f"its cameras are for {p.width}x{p.height} images ({panels} panel(s)), "
                         f"the run renders {W * panels}x{H}", f"--size {p.width // panels}x{p.height}, "
                         "or the camera file of a run at this size")
    missing = [int(f) for f in frames if p.views_for(int(f)) is None]
    if missing:
        raise InputError(Mark(p.source), f"has no camera for frame {missing[0]} ({len(missing)} frame(s) missing) "
                         "and its camera moves between frames", "the frames it holds: "
                         + ",".join(str(f) for f, _ in p.frames[:12]) + (" ..." if len(p.frames) > 12 else ""))


# ----------------------------------------------------------------------------- one parser per setting


def _ranged(key: str, v, where: Mark, integer: bool = False):
    lo, hi = RANGES[key]
    return check_number(v, where, key, lo=lo, hi=hi, integer=integer)


def _numbers_text(v):
    """``"1,2,3"`` / ``"512x256"`` → [1.0, 2.0, 3.0] / [512.0, 256.0]; anything else unchanged."""
    if isinstance(v, str) and re.fullmatch(r"\s*[-+0-9.eE]+(\s*[,xX]\s*[-+0-9.eE]+)+\s*", v):
        try:
            return [float(x) for x in re.split(r"\s*[,xX]\s*", v.strip())]
        except ValueError:
            return v
    return v


def parse_size(v, where: Mark) -> tuple[int, int]:
    """``[W, H]`` or ``"WxH"`` (either, in YAML and on the command line)."""
    v = _numbers_text(v)
    allowed = f"size is exactly 2 whole numbers [W, H] or WxH, {RANGES['size'][0]}..{RANGES['size'][1]} pixels"
    if not isinstance(v, list):
        raise InputError(where, f"size is {v!r}", allowed)
    if len(v) != 2:
        raise InputError(where, f"size has {len(v)} values", allowed)
    w, h = (_ranged("size", x, where, integer=True) for x in v)
    return int(w), int(h)


def parse_point(v, where: Mark, what: str) -> tuple[float, float, float]:
    """``[x, y, z]`` or ``"x,y,z"``."""
    return check_vector(_numbers_text(v), where, what, 3)


def parse_background(v, where: Mark) -> tuple[float, float, float, float]:
    if v == "transparent":
        return (0.0, 0.0, 0.0, 0.0)
    v = _numbers_text(v)
    allowed = "background is [r, g, b], [r, g, b, a] (linear, 0..1), R,G,B[,A] or 'transparent'"
    if not isinstance(v, list) or len(v) not in (3, 4):
        raise InputError(where, f"background is {v!r}", allowed)
    marks = getattr(v, "item_marks", None) or [where] * len(v)
    vals = [float(_ranged("background", x, m)) for x, m in zip(v, marks)]
    return tuple(vals + [1.0] * (4 - len(vals)))


def parse_device(v, where: Mark) -> int | None:
    if v == "default":
        return None
    if isinstance(v, str):
        raise InputError(where, f"device is the string {v!r}", "device is 'default' or an EGL device index (0, 1, ...)")
    return int(_ranged("device", v, where, integer=True))


def parse_target(v, where: Mark, what: str = "target"):
    """A camera target: ``[x, y, z]`` / ``"x,y,z"`` (a point), or ``bone:NAME`` / ``{bone: NAME}``
    (a bone, returned as the string ``bone:NAME``)."""
    if isinstance(v, dict) and set(v) == {"bone"} and isinstance(v["bone"], str):
        v = "bone:" + v["bone"]
    if isinstance(v, str) and v.startswith("bone:"):
        if not is_name(v[5:]):
            raise InputError(where, f"{what} names the bone {v[5:]!r}", f"bone:NAME with a bone name ({NAME_ALLOWED})")
        return v
    if isinstance(v, (dict, str)) and not isinstance(_numbers_text(v), list):
        raise InputError(where, f"{what} is {v!r}", "a point [x, y, z] or x,y,z, or a bone: bone:NAME or {bone: NAME}")
    return parse_point(v, where, what)


def _with_target(cam: CameraSpec, target, where: Mark) -> CameraSpec:
    if isinstance(target, str):
        return replace(cam, target=None, target_bone=target[5:], target_mark=where)
    return replace(cam, target=target, target_bone=None, target_mark=None)


def parse_camera(value, where: Mark, fov: float = DEFAULT_FOV) -> CameraSpec:
    f = Fields(value, where, "camera", keys=("position", "target", "offset", "up", "fov"))
    position = parse_point(f.raw("position"), f.vmark("position"), "position") if f.has("position") else None
    cam = CameraSpec(position=position)
    if f.has("target"):
        cam = _with_target(cam, parse_target(f.raw("target"), f.vmark("target")), f.vmark("target"))
    offset = parse_point(f.raw("offset"), f.vmark("offset"), "offset") if f.has("offset") else None
    up = parse_point(f.raw("up"), f.vmark("up"), "up") if f.has("up") else (0.0, 0.0, 1.0)
    fov = float(_ranged("fov", f.raw("fov"), f.vmark("fov"))) if f.has("fov") else fov
    f.done()
    cam = replace(cam, offset=offset, up=up, fov=fov)
    at = {k: f.vmark(k) for k in ("position", "target", "offset", "up") if f.has(k)}
    check_camera(cam, at.get("up") or at.get("position") or at.get("offset") or where,
                 at.get("position") or where, at.get("offset") or where)
    return cam


def check_camera(cam: CameraSpec, where_up: Mark, where_pos: Mark, where_offset: Mark | None = None) -> None:
    """A camera that can be built: a position unless the target is a bone, an offset only with
    a bone target and without a position, a viewing direction that is not along ``up``."""
    allowed = ("give position [x, y, z]; or a bone target (target: bone:NAME) with a position, an offset, "
               "or neither (the camera moves with the bone)")
    if cam.offset is not None:
        if cam.target_bone is None:
            raise InputError(where_offset or where_pos, "a camera offset without a bone target", allowed)
        if cam.position is not None:
            raise InputError(where_offset or where_pos, "both a camera position and an offset are given",
                             "a position (a fixed camera) or an offset (a camera that moves with the bone)")
        d = tuple(-x for x in cam.offset)
    elif cam.position is None:
        if cam.target_bone is None:
            raise InputError(where_pos, "the camera has no position", allowed)
        return  # the automatic direction (view auto)
    elif cam.target is None:
        return  # checked against the framing centre or the bone when the camera is built
    else:
        d = tuple(p - t for p, t in zip(cam.position, cam.target))
    if sum(x * x for x in d) < 1e-12:
        raise InputError(where_offset if cam.offset is not None else where_pos, "camera position equals its target",
                         "put the camera away from the target")
    up = cam.up
    cross = (d[1] * up[2] - d[2] * up[1], d[2] * up[0] - d[0] * up[2], d[0] * up[1] - d[1] * up[0])
    if sum(x * x for x in cross) < 1e-12 * max(sum(x * x for x in d), 1e-12):
        raise InputError(where_up, "camera up is parallel to the viewing direction",
                         "give an up vector not parallel to target - position")


def parse_render_settings(value, where: Mark) -> RenderSettings:
    """Read the job file's ``render:`` mapping (None: rendering off, defaults)."""
    if value is None:
        return RenderSettings()
    f = Fields(value, where, "render", keys=("enabled", "size", "view", "fov", "camera", "orbit", "wireframe",
                                             "background", "bones", "supersample", "device", "skin"))
    d = RenderSettings()
    enabled = f.boolean("enabled", default=True)
    size = parse_size(f.raw("size"), f.vmark("size")) if f.has("size") else d.size
    view = f.choice("view", VIEWS, default=d.view)
    fov = float(_ranged("fov", f.raw("fov"), f.vmark("fov"))) if f.has("fov") else d.fov
    camera = None
    if f.has("camera"):
        if f.has("view"):
            raise InputError(f.kmark("camera"), "both 'camera' and 'view' are given",
                             "give an explicit camera or a named view, not both")
        camera = parse_camera(f.raw("camera"), f.vmark("camera"), fov)
    orbit = float(_ranged("orbit", f.raw("orbit"), f.vmark("orbit"))) if f.has("orbit") else d.orbit
    wireframe = f.boolean("wireframe", default=d.wireframe)
    background = parse_background(f.raw("background"), f.vmark("background")) if f.has("background") \
        else d.background
    bones = f.boolean("bones", default=d.bones)
    supersample = int(_ranged("supersample", f.raw("supersample"), f.vmark("supersample"), integer=True)) \
        if f.has("supersample") else d.supersample
    device = parse_device(f.raw("device"), f.vmark("device")) if f.has("device") else d.device
    skin = f.choice("skin", SKIN_VIEWS, default=d.skin)
    f.done()
    return RenderSettings(enabled=enabled, size=size, view=view, fov=fov, camera=camera, orbit=orbit,
                          wireframe=wireframe, background=background, bones=bones,
                          supersample=supersample, device=device, skin=skin)


# ----------------------------------------------------------------------------- command line

def add_render_args(parser: argparse.ArgumentParser) -> None:
    """Render flags shared by ``axdf run`` and ``axdf render``; all default to 'not given'.
    Their values are read by the same parsers as the ``render:`` block."""
    def rng(key):
        return f"{RANGES[key][0]:g}..{RANGES[key][1]:g}"

    g = parser.add_argument_group("rendering")
    g.add_argument("--size", metavar="WxH", help=f"output size in pixels per view ({rng('size')}): 512x512 or [512, 512]")
    g.add_argument("--view", choices=VIEWS, help="named view (auto = three-quarter front)")
    g.add_argument("--fov", metavar="DEG", help=f"vertical field of view, degrees ({rng('fov')})")
    g.add_argument("--camera-position", metavar="X,Y,Z", help="explicit camera position (world, metres)")
    g.add_argument("--camera-target", metavar="X,Y,Z|bone:NAME",
                   help="point the explicit camera looks at (default: the centre of the framing), or a bone "
                        "it aims at every frame (with no --camera-position: a camera that moves with the bone)")
    g.add_argument("--camera-offset", metavar="X,Y,Z",
                   help="with --camera-target bone:NAME: the camera moves with the bone at this offset (world, m)")
    g.add_argument("--camera-up", metavar="X,Y,Z", help="explicit camera's up direction (default 0,0,1)")
    g.add_argument("--camera", metavar="CAMERA.json", dest="camera_file",
                   help="render through the cameras of this camera.json (an earlier run's, e.g. a golden's), "
                        "frame by frame, instead of framing the subject (docs/COMPARE.md)")
    g.add_argument("--orbit", metavar="DEG", help=f"turntable: degrees per frame about +Z ({rng('orbit')})")
    g.add_argument("--wireframe", action=argparse.BooleanOptionalAction, default=None,
                   help="edge overlay")
    g.add_argument("--bones", action=argparse.BooleanOptionalAction, default=None,
                   help="draw bone meshes (sticks for bones without one)")
    g.add_argument("--skin-view", choices=SKIN_VIEWS,
                   help="a run with a skin (axdf run --skin): draw it over the muscles (see-through, default), "
                        "as an opaque body, or not at all")
    g.add_argument("--background", metavar="R,G,B[,A]|transparent",
                   help="background colour (linear 0..1) or 'transparent'")
    g.add_argument("--supersample", metavar="N", help=f"anti-aliasing factor {rng('supersample')}")
    g.add_argument("--device", metavar="default|N", help="EGL device index")
    g.add_argument("--egl-library", metavar="PATH",
                   help="EGL library to load instead of the system's libEGL.so.1 (diagnosis)")


def _flag(args, name: str):
    """(value read as YAML, Mark naming the flag) of a given flag, or (None, None)."""
    text = getattr(args, name, None)
    if text is None:
        return None, None
    flag = "--" + name.replace("_", "-")
    where = Mark(flag)
    if not isinstance(text, str):
        return text, where
    try:
        value = _plain(parse_yaml(text, flag))  # positions inside a flag's text mean nothing
    except InputError:
        value = text
    return (text if value is None else value), where


def _plain(v):
    if isinstance(v, list):
        return [_plain(x) for x in v]
    if isinstance(v, dict):
        return {k: _plain(x) for k, x in v.items()}
    return v


def settings_from_args(settings: RenderSettings, args: argparse.Namespace) -> RenderSettings:
    """Apply the flags of :func:`add_render_args` that were given; bad values are InputErrors
    naming the flag (exit 2)."""
    s = settings
    v, w = _flag(args, "size")
    if w:
        s = replace(s, size=parse_size(v, w))
    if getattr(args, "view", None) is not None:
        s = replace(s, view=args.view, camera=None)
    v, w = _flag(args, "fov")
    if w:
        fov = float(_ranged("fov", v, w))
        s = replace(s, fov=fov, camera=replace(s.camera, fov=fov) if s.camera else None)
    s = _camera_flags(s, args)
    v, w = _flag(args, "orbit")
    if w:
        s = replace(s, orbit=float(_ranged("orbit", v, w)))
    if getattr(args, "wireframe", None) is not None:
        s = replace(s, wireframe=bool(args.wireframe))
    if getattr(args, "bones", None) is not None:
        s = replace(s, bones=bool(args.bones))
    if getattr(args, "skin_view", None) is not None:
        s = replace(s, skin=args.skin_view)
    v, w = _flag(args, "background")
    if w:
        s = replace(s, background=parse_background(v, w))
    v, w = _flag(args, "supersample")
    if w:
        s = replace(s, supersample=int(_ranged("supersample", v, w, integer=True)))
    v, w = _flag(args, "device")
    if w:
        s = replace(s, device=parse_device(v, w))
    if getattr(args, "egl_library", None) is not None:
        s = replace(s, egl_library=args.egl_library)
    if getattr(args, "camera_file", None) is not None:
        s = replace(s, pinned=read_pinned_cameras(args.camera_file))
    return s


def _camera_flags(s: RenderSettings, args) -> RenderSettings:
    pos, wp = _flag(args, "camera_position")
    tgt, wt = _flag(args, "camera_target")
    off, wo = _flag(args, "camera_offset")
    up, wu = _flag(args, "camera_up")
    if not (wp or wt or wo or wu):
        return s
    if getattr(args, "view", None) is not None:
        raise InputError(Mark("--view"), "both --view and --camera-* are given",
                         "give an explicit camera or a named view, not both")
    target = parse_target(tgt, wt, "camera target") if wt else None
    cam = s.camera
    if cam is None and not wp and not isinstance(target, str):
        raise InputError(wt or wo or wu, "an explicit camera needs --camera-position or --camera-target bone:NAME",
                         "give --camera-position X,Y,Z, or --camera-target bone:NAME")
    cam = cam or CameraSpec(position=None, fov=s.fov)
    if wp:  # a new position replaces an offset, a new offset a position
        cam = replace(cam, position=parse_point(pos, wp, "camera position"), offset=None)
    if wo:
        cam = replace(cam, offset=parse_point(off, wo, "camera offset"), position=None)
    if wt:
        cam = _with_target(cam, target, wt)
    if wu:
        cam = replace(cam, up=parse_point(up, wu, "camera up"))
    check_camera(cam, wu or wp or wt or wo, wp or wt or wo, wo)
    return replace(s, camera=cam, view="auto")


def settings_to_dict(s: RenderSettings) -> dict:
    """The settings as the job file's ``render:`` mapping (for the manifest; re-read by
    :func:`parse_render_settings`). The EGL device and library are machine choices: omitted."""
    d = {"enabled": s.enabled, "size": list(s.size), "fov": s.fov, "orbit": s.orbit,
         "wireframe": s.wireframe, "background": list(s.background), "bones": s.bones,
         "supersample": s.supersample}
    if s.skin != RenderSettings.skin:  # (the default is not written: manifests of runs before skins read the same)
        d["skin"] = s.skin
    if s.pinned is not None:  # (not re-read: a render of the run frames it by its recorded framing)
        d["camera_file"] = {"sha256": s.pinned.sha256}
    if s.camera is not None:
        c = s.camera
        d["camera"] = {k: v for k, v in (
            ("position", list(c.position) if c.position is not None else None),
            ("target", "bone:" + c.target_bone if c.target_bone is not None
             else list(c.target) if c.target is not None else None),
            ("offset", list(c.offset) if c.offset is not None else None),
            ("up", list(c.up)), ("fov", c.fov)) if v is not None}
    else:
        d["view"] = s.view
    return d
