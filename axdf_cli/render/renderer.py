"""The moderngl renderer: muscles and bones to a shaded preview and exact data passes.

Per frame and per panel (view) two passes are drawn:

1. **beauty**: shaded colour at ``supersample`` times the output size into a half-float
   RGBA target, read back and box-downsampled in numpy (float32, fixed order), which is
   exactly repeatable, unlike driver MSAA. Shading is done in camera space: a soft
   (wrapped Lambert) key light from upper left, a weaker fill from the right, a hemisphere
   ambient and a small Blinn highlight; optional wireframe overlay. Colours are linear and
   premultiplied by alpha.
2. **data**: at the output size, one sample per pixel centre, no blending: world normal and
   camera depth (RGBA float32) and the object id (R float32 holding exact integers below
   2^24). Background: id 0, depth 0, normal 0.

Ids: 0 = background, ``1 .. M`` = ``Scene.muscles`` in order, ``M+1 .. M+B`` = bones,
then ``M+B+1 ..`` the scene's layers (the parts the stages add) in order: each drawn opaque
with its colour, the skin as its settings say (its id is in the id pass when opaque).

The **skin** (``Scene.skin``, a run with ``--skin``) is drawn as ``RenderSettings.skin`` says:
``opaque`` like any surface, in both passes (the data passes see the body); ``see-through``
after everything else in the beauty pass only, blended over what lies behind it with its
front faces alone, more opaque where it turns away from the eye (its outline stays), so the
data passes see the muscles under it; ``off``: not drawn.

An optional **amodal** pass (:meth:`Renderer.amodal`, data sets) gives each muscle's full
extent in the image, occluders ignored: every muscle is drawn without depth test into its
own channel of a few RGBA8 targets (4 channels x MASK_TARGETS targets: 16 muscles per
draw round), blended with MAX so that a channel is 1 wherever any of its muscle's triangles
covers the pixel centre (the sampling of the data pass, so a visible muscle pixel of the
``id`` pass is always inside its amodal mask).

Bones: a bone with a mesh is drawn as its mesh; a bone without one as a stick (a thin
cylinder) from its parent's joint to its own, so a skeleton without meshes still shows
(:class:`BoneLayout` turns a skeleton's poses into the scene bones' transforms).

Speed: each mesh's topology (index buffer) and each bone mesh are uploaded once; per frame
only muscle positions and normals are written (one buffer write each) and each target is
read back once.
"""
from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Iterable, Iterator

import numpy as np

from axdf_cli.parts import Kind
from axdf_cli.render.camera import Camera, sequence_cameras
from axdf_cli.render.context import check_same_process
from axdf_cli.render.framing import placed_plates
from axdf_cli.specs.render import RenderSettings
from axdf_cli.render.scene import FrameChunk, Scene, SceneBone

BONE_COLOR = (0.78, 0.75, 0.68)  # neutral ivory, linear RGB
STICK_SIDES = 12  # a stick is a 12-sided cylinder with flat caps
STICK_RADIUS_FRACTION = 0.01  # stick radius per metre of the subject's largest extent (a stick a few pixels wide when the skeleton is framed)
STICK_MIN_RADIUS = 0.002  # metres
WIRE_DARKEN = 0.55  # wire colour = albedo * this
WIRE_DEPTH_BIAS = 2e-4  # NDC depth pulled towards the camera so edges win over their faces
BACKGROUND_ID = 0
SKIN_ALPHA = 0.22  # see-through skin: its opacity facing the eye ...
SKIN_RIM_ALPHA = 0.8  # ... and where it turns away (its outline)
MASK_TARGETS = 4  # RGBA8 colour attachments of the amodal pass: 16 muscles per round

_MASK_VERT = """
#version 330
uniform mat4 u_view;
uniform mat4 u_proj;
in vec3 in_pos;
void main() { gl_Position = u_proj * (u_view * vec4(in_pos, 1.0)); }
"""

_MASK_FRAG = """
#version 330
uniform int u_target;   // which attachment holds this muscle
uniform vec4 u_channel; // and which of its channels
%s
void main() {
%s
}
""" % ("\n".join(f"layout(location = {k}) out vec4 f_mask{k};" for k in range(MASK_TARGETS)),
       "\n".join(f"    f_mask{k} = u_target == {k} ? u_channel : vec4(0.0);" for k in range(MASK_TARGETS)))

_VERT = """
#version 330
uniform mat4 u_model;   // object to world (identity for muscles)
uniform mat4 u_view;    // world to camera (OpenCV axes)
uniform mat4 u_proj;    // camera to clip
uniform float u_bias;   // NDC depth bias (wireframe)
in vec3 in_pos;
in vec3 in_nrm;
out vec3 v_nrm;         // world normal
out vec3 v_cam;         // camera-space position
void main() {
    vec4 w = u_model * vec4(in_pos, 1.0);
    vec4 c = u_view * w;
    v_cam = c.xyz;
    v_nrm = mat3(u_model) * in_nrm;
    gl_Position = u_proj * c;
    gl_Position.z -= u_bias * gl_Position.w;
}
"""

_BEAUTY_FRAG = """
#version 330
uniform mat4 u_view;
uniform vec3 u_albedo;
uniform int u_wire;
uniform float u_alpha;  // 1: opaque; below: see-through, rising to u_rim at grazing angles
uniform float u_rim;
in vec3 v_nrm;
in vec3 v_cam;
out vec4 f_color;
float wrap(float x, float w) { return max((x + w) / (1.0 + w), 0.0); }
void main() {
    if (u_wire == 1) { f_color = vec4(u_albedo * %(wire)f, 1.0); return; }
    vec3 n = normalize(mat3(u_view) * v_nrm);
    vec3 e = normalize(-v_cam);               // towards the eye
    if (dot(n, e) < 0.0) n = -n;               // inside faces seen through an opening
    // lights in camera axes (x right, y down, z forward), pointing towards the light
    vec3 key = normalize(vec3(-0.45, -0.65, -0.60));
    vec3 fill = normalize(vec3(0.75, -0.10, -0.65));
    vec3 rim = normalize(vec3(0.10, -0.60, 0.80));
    float hemi = 0.5 - 0.5 * n.y;              // 1 facing up in the image
    vec3 ambient = mix(vec3(0.08, 0.075, 0.07), vec3(0.22, 0.23, 0.25), hemi);
    float d = 0.95 * wrap(dot(n, key), 0.2) + 0.25 * wrap(dot(n, fill), 0.4)
            + 0.20 * pow(max(dot(n, rim), 0.0), 2.0);
    vec3 h = normalize(key + e);
    float spec = 0.18 * pow(max(dot(n, h), 0.0), 40.0);
    vec3 c = u_albedo * (ambient + vec3(d)) + vec3(spec);
    float a = u_alpha >= 1.0 ? 1.0 : mix(u_alpha, u_rim, pow(1.0 - abs(dot(n, e)), 2.0));
    f_color = vec4(min(c, vec3(1.0)) * a, a);  // premultiplied
}
""" % {"wire": WIRE_DARKEN}

_DATA_FRAG = """
#version 330
uniform float u_id;
in vec3 v_nrm;
in vec3 v_cam;
layout(location = 0) out vec4 f_data;  // world normal xyz, camera depth
layout(location = 1) out vec4 f_id;
void main() {
    f_data = vec4(normalize(v_nrm), v_cam.z);
    f_id = vec4(u_id, 0.0, 0.0, 0.0);
}
"""


@dataclass(frozen=True)
class FrameImages:
    """One rendered frame (all panels of a sheet side by side)."""

    frame: int
    rgba: np.ndarray  # (H, W, 4) float32 linear, premultiplied alpha
    depth: np.ndarray  # (H, W) float32 camera z in metres, 0 = background
    normals: np.ndarray  # (H, W, 3) float32 world unit normals, 0 = background
    ids: np.ndarray  # (H, W) uint32, 0 = background, 1..M muscles, M+1.. bones
    cameras: tuple[Camera, ...]
    under: tuple[np.ndarray, np.ndarray] | None = None  # an opaque skin's under_id, under_depth (render/under.py)
    parts: np.ndarray | None = None  # (H, W) an opaque skin's body-part ids (render/under.py body_parts)


def vertex_normals(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """(V, 3) float32 area-weighted unit vertex normals of a (V, 3) / (T, 3) mesh."""
    v = vertices.astype(np.float64)
    tri = v[faces]  # (T, 3, 3)
    fn = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])  # (T, 3), |.| = 2 area
    n = np.zeros_like(v)
    for k in range(3):
        np.add.at(n, faces[:, k], fn)
    length = np.linalg.norm(n, axis=1, keepdims=True)
    return (n / np.where(length > 0, length, 1.0)).astype(np.float32)


def unit_stick(sides: int = STICK_SIDES) -> tuple[np.ndarray, np.ndarray]:
    """A closed cylinder of radius 1 from z = 0 to z = 1: (V, 3) float32, (T, 3) int32,
    outward; sides and caps have their own vertices (crisp normals)."""
    a = 2 * np.pi * np.arange(sides) / sides
    ring = np.stack([np.cos(a), np.sin(a)], axis=1)
    side = np.concatenate([np.c_[ring, np.zeros(sides)], np.c_[ring, np.ones(sides)]])  # 0..2s-1
    caps = np.concatenate([side, [[0, 0, 0], [0, 0, 1]]])  # 2s..4s-1 rings, 4s, 4s+1 centres
    k = np.arange(sides)
    n = (k + 1) % sides
    faces = [np.stack([k, n, sides + n], 1), np.stack([k, sides + n, sides + k], 1),
             np.stack([np.full(sides, 4 * sides), 2 * sides + n, 2 * sides + k], 1),
             np.stack([np.full(sides, 4 * sides + 1), 3 * sides + k, 3 * sides + n], 1)]
    return np.concatenate([side, caps]).astype(np.float32), np.concatenate(faces).astype(np.int32)


@dataclass(frozen=True)
class BoneLayout:
    """The scene bones of a skeleton: each bone's mesh, or for a bone without one a stick
    from its parent's joint to its own; :meth:`transforms` poses them."""

    bones: tuple[SceneBone, ...]
    sources: tuple[tuple[int, int], ...]  # per scene bone: (bone, -1) for a mesh, (bone, parent) for a stick
    radius: float  # stick radius, metres

    def transforms(self, world: np.ndarray) -> np.ndarray:
        """(C, n_scene_bones, 4, 4) model matrices from the skeleton's (C, B, 4, 4) world
        transforms: a mesh's bone frame, or a stick's scaled frame along parent -> joint."""
        out = np.empty((world.shape[0], len(self.sources), 4, 4))
        for k, (b, parent) in enumerate(self.sources):
            out[:, k] = world[:, b] if parent < 0 else stick_matrices(world[:, parent, :3, 3], world[:, b, :3, 3],
                                                                      self.radius)
        return out


def bone_layout(names, parents, meshes: dict, extent: float) -> BoneLayout:
    """``names`` of every bone and ``parents``: the bone a stick joins it to (-1: none, see
    :meth:`axdf_cli.model.skeleton.Skeleton.stick_parents`); ``meshes``: bone index -> (vertices,
    faces) bone-local; ``extent``: the subject's largest extent (stick radius)."""
    radius = max(STICK_MIN_RADIUS, STICK_RADIUS_FRACTION * extent)
    stick_v, stick_f = unit_stick()
    bones, sources = [], []
    for b, (name, parent) in enumerate(zip(names, parents)):
        if b in meshes:
            bones.append(SceneBone(name, *meshes[b]))
            sources.append((b, -1))
        elif parent >= 0:
            bones.append(SceneBone(name, stick_v, stick_f))
            sources.append((b, parent))
    return BoneLayout(tuple(bones), tuple(sources), float(radius))


def stick_matrices(a: np.ndarray, b: np.ndarray, radius: float) -> np.ndarray:
    """(C, 4, 4) matrices taking :func:`unit_stick` onto cylinders of ``radius`` from ``a`` to
    ``b`` (C, 3); a zero-length stick collapses to a point (draws nothing)."""
    d = b - a
    length = np.linalg.norm(d, axis=1, keepdims=True)
    z = np.where(length > 1e-12, d / np.maximum(length, 1e-300), [0.0, 0.0, 1.0])
    helper = np.where(np.abs(z[:, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
    x = np.cross(helper, z)
    x /= np.linalg.norm(x, axis=1, keepdims=True)
    y = np.cross(z, x)
    m = np.zeros((len(a), 4, 4))
    m[:, :3, 0] = x * radius
    m[:, :3, 1] = y * radius
    m[:, :3, 2] = z * length
    m[:, :3, 3] = a
    m[:, 3, 3] = 1.0
    return m


def downsample(img: np.ndarray, s: int) -> np.ndarray:
    """Box filter: (H*s, W*s, C) -> (H, W, C) float32 mean of each s x s block.

    Sums the s rows, then the s columns, of each block in a fixed order with float32
    additions (exactly repeatable; faster than a strided ``sum(axis=(1, 3))``).
    """
    x = img.astype(np.float32, copy=False)
    if s == 1:
        return x
    Hs, Ws, C = x.shape
    rows = x.reshape(Hs // s, s, Ws, C)
    acc = rows[:, 0].copy()  # (H, W*s, C)
    for i in range(1, s):
        acc += rows[:, i]
    cols = acc.reshape(Hs // s, Ws // s, s, C)
    out = cols[:, :, 0].copy()  # (H, W, C)
    for j in range(1, s):
        out += cols[:, :, j]
    out *= np.float32(1.0 / (s * s))
    return out


def panels(img: "FrameImages"):
    """Each panel of a frame: (its slice of the image, its camera's K within the panel, the
    camera)."""
    for cam in img.cameras:
        x0, y0, w, h = cam.viewport
        K = np.array(cam.K, dtype=np.float64)
        K[0, 2] -= x0
        K[1, 2] -= y0
        yield (slice(y0, y0 + h), slice(x0, x0 + w)), K, cam


def layer_id(scene: Scene, k: int) -> int:
    """The id of the scene's layer ``k`` in the ``id`` pass (after every muscle and scene bone)."""
    return 1 + len(scene.muscles) + len(scene.bones) + k


def skin_id(scene: Scene) -> int:
    """The opaque skin's id in the ``id`` pass (its layer's)."""
    return layer_id(scene, scene.skin_index)


def id_map(scene: Scene, bones: bool, skin: str = "off") -> dict:
    """``camera.json``'s id table: id (as a string key) -> {kind, name}; ``skin``: how the
    skin is drawn (it has an id when opaque)."""
    out = {str(BACKGROUND_ID): {"kind": "background", "name": None}}
    for i, m in enumerate(scene.muscles):
        out[str(1 + i)] = {"kind": "muscle", "name": m.name}
    if bones:
        for j, b in enumerate(scene.bones):
            out[str(1 + len(scene.muscles) + j)] = {"kind": "bone", "name": b.name}
    for k, layer in enumerate(scene.layers):  # (a skin has an id where it is drawn opaque)
        if Kind(layer.kind) is not Kind.SKIN or skin == "opaque":
            out[str(layer_id(scene, k))] = {"kind": Kind(layer.kind).value, "name": layer.name}
    return out


class Renderer:
    """Holds GL resources for one Scene; :meth:`render` draws one frame."""

    def __init__(self, ctx, scene: Scene, settings: RenderSettings, cameras_panels: int = 1):
        check_same_process(ctx)
        self.ctx = ctx
        self.scene = scene
        self.settings = settings
        s = settings.supersample
        W, H = settings.size
        self.size = (W * cameras_panels, H)
        self.prog = ctx.program(vertex_shader=_VERT, fragment_shader=_BEAUTY_FRAG)
        self.dprog = ctx.program(vertex_shader=_VERT, fragment_shader=_DATA_FRAG)
        # targets
        Wt, Ht = self.size
        self.color_tex = ctx.texture((Wt * s, Ht * s), 4, dtype="f2")
        self.color_fbo = ctx.framebuffer([self.color_tex], ctx.depth_renderbuffer((Wt * s, Ht * s)))
        self.data_tex = ctx.texture((Wt, Ht), 4, dtype="f4")
        self.id_tex = ctx.texture((Wt, Ht), 4, dtype="f4")
        self.data_fbo = ctx.framebuffer([self.data_tex, self.id_tex], ctx.depth_renderbuffer((Wt, Ht)))
        # muscles: topology once, dynamic positions and normals
        self.muscles = []
        for i, m in enumerate(scene.muscles):
            nv = int(m.faces.max()) + 1 if len(m.faces) else 0
            ibo = ctx.buffer(np.ascontiguousarray(m.faces, dtype=np.int32).tobytes())
            vpos = ctx.buffer(reserve=max(nv, 1) * 12, dynamic=True)
            vnrm = ctx.buffer(reserve=max(nv, 1) * 12, dynamic=True)
            vao = ctx.vertex_array(self.prog, [(vpos, "3f", "in_pos"), (vnrm, "3f", "in_nrm")],
                                   index_buffer=ibo, index_element_size=4)
            dvao = ctx.vertex_array(self.dprog, [(vpos, "3f", "in_pos"), (vnrm, "3f", "in_nrm")],
                                    index_buffer=ibo, index_element_size=4)
            self.muscles.append((vpos, vnrm, vao, dvao, tuple(float(c) for c in m.color), float(1 + i)))
        # bones: static meshes in bone-local coordinates, placed by a model matrix
        self.bones = []
        if settings.bones:
            for j, b in enumerate(scene.bones):
                if len(b.faces) == 0:
                    continue  # nothing to draw (its id stays reserved)
                v = np.ascontiguousarray(b.vertices, dtype=np.float32)
                n = vertex_normals(v, b.faces)
                vbo = ctx.buffer(np.concatenate([v, n], axis=1).tobytes())
                ibo = ctx.buffer(np.ascontiguousarray(b.faces, dtype=np.int32).tobytes())
                vao = ctx.vertex_array(self.prog, [(vbo, "3f 3f", "in_pos", "in_nrm")],
                                       index_buffer=ibo, index_element_size=4)
                dvao = ctx.vertex_array(self.dprog, [(vbo, "3f 3f", "in_pos", "in_nrm")],
                                        index_buffer=ibo, index_element_size=4)
                self.bones.append((j, vao, dvao, float(1 + len(scene.muscles) + j)))
        self.skin = None  # (positions, normals, vao, data vao): the skin when it is drawn
        self.layers = {}  # layer index -> (positions, normals, vao, data vao, colour, id): the others, opaque
        for k, layer in enumerate(scene.layers):
            skin = Kind(layer.kind) is Kind.SKIN
            if not len(layer.faces) or (skin and (k != scene.skin_index or settings.skin == "off")):
                continue
            nv = int(layer.faces.max()) + 1
            ibo = ctx.buffer(np.ascontiguousarray(layer.faces, dtype=np.int32).tobytes())
            vpos = ctx.buffer(reserve=nv * 12, dynamic=True)
            vnrm = ctx.buffer(reserve=nv * 12, dynamic=True)
            vao = ctx.vertex_array(self.prog, [(vpos, "3f", "in_pos"), (vnrm, "3f", "in_nrm")],
                                   index_buffer=ibo, index_element_size=4)
            dvao = ctx.vertex_array(self.dprog, [(vpos, "3f", "in_pos"), (vnrm, "3f", "in_nrm")],
                                    index_buffer=ibo, index_element_size=4)
            if skin:
                self.skin = (vpos, vnrm, vao, dvao)
            else:
                self.layers[k] = (vpos, vnrm, vao, dvao, tuple(float(c) for c in layer.color),
                                  float(layer_id(scene, k)))
        self._ident = np.eye(4, dtype="f4").T.tobytes()
        self._mask = None  # the amodal pass's program, targets and vertex arrays: made on first use

    # ---------------------------------------------------------------------------------------
    def _draw_all(self, prog, data: bool, bone_world: np.ndarray | None, wire: bool = False):
        for vpos, vnrm, vao, dvao, color, ident in self.muscles:
            self._draw(prog, data, wire, self._ident, (vao, dvao), color, ident)
        for j, vao, dvao, ident in self.bones:
            self._draw(prog, data, wire, np.asarray(bone_world[j], dtype="f4").T.tobytes(), (vao, dvao), BONE_COLOR,
                       ident)
        for vpos, vnrm, vao, dvao, color, ident in self.layers.values():
            self._draw(prog, data, wire, self._ident, (vao, dvao), color, ident)
        if self.skin is not None and self.settings.skin == "opaque":
            self._draw(prog, data, wire, self._ident, (self.skin[2], self.skin[3]), self.scene.skin.color,
                       float(skin_id(self.scene)))

    @staticmethod
    def _draw(prog, data: bool, wire: bool, model: bytes, vaos: tuple, color, ident: float) -> None:
        """One mesh: into the data targets (its id) or the beauty target (its colour)."""
        prog["u_model"].write(model)
        if data:
            prog["u_id"].value = ident
            vaos[1].render()
        else:
            prog["u_albedo"].value = color
            prog["u_wire"].value = int(wire)
            vaos[0].render()

    def _draw_see_through_skin(self) -> None:
        """The see-through skin over what the beauty target holds: front faces only, blended
        (premultiplied alpha), leaving the depth buffer as the surfaces under it left it."""
        ctx, prog = self.ctx, self.prog
        prog["u_model"].write(self._ident)
        prog["u_albedo"].value = self.scene.skin.color
        prog["u_wire"].value = 0
        prog["u_alpha"].value = SKIN_ALPHA
        prog["u_rim"].value = SKIN_RIM_ALPHA
        ctx.enable_only(ctx.DEPTH_TEST | ctx.BLEND | ctx.CULL_FACE)
        ctx.blend_func = ctx.ONE, ctx.ONE_MINUS_SRC_ALPHA
        self.color_fbo.depth_mask = False
        try:
            self.skin[2].render()
        finally:
            self.color_fbo.depth_mask = True
            ctx.enable_only(ctx.DEPTH_TEST)
            prog["u_alpha"].value = 1.0

    def render(self, frame: int, positions, normals, bone_world: np.ndarray | None,
               cameras: list[Camera], layers=()) -> FrameImages:
        """Draw one frame.

        ``positions`` / ``normals``: per muscle (V_m, 3) float32 world arrays;
        ``bone_world``: (n_bones, 4, 4) float64; ``cameras``: one per panel; ``layers``: per
        scene layer its (V, 3) positions and normals.
        """
        ctx = self.ctx
        check_same_process(ctx)
        s = self.settings.supersample
        for (vpos, vnrm, *_), p, n in zip(self.muscles, positions, normals):
            vpos.write(np.ascontiguousarray(p, dtype=np.float32).tobytes())
            vnrm.write(np.ascontiguousarray(n, dtype=np.float32).tobytes())
        if len(layers) != len(self.scene.layers):
            raise ValueError(f"frame {frame}: the scene has {len(self.scene.layers)} layer(s) and the frame "
                             f"{len(layers)}")
        for k, (p, n) in enumerate(layers):
            buffers = self.skin if k == self.scene.skin_index else self.layers.get(k)
            if buffers is not None:
                buffers[0].write(np.ascontiguousarray(p, dtype=np.float32).tobytes())
                buffers[1].write(np.ascontiguousarray(n, dtype=np.float32).tobytes())
        self.prog["u_alpha"].value = 1.0
        ctx.enable_only(ctx.DEPTH_TEST)
        bg = self.settings.background
        Wt, Ht = self.size
        # beauty pass (supersampled)
        self.color_fbo.use()
        self.color_fbo.clear(bg[0] * bg[3], bg[1] * bg[3], bg[2] * bg[3], bg[3], depth=1.0)
        for cam in cameras:
            x0, y0, w, h = cam.viewport
            self.color_fbo.viewport = (x0 * s, (Ht - y0 - h) * s, w * s, h * s)
            self.prog["u_view"].write(np.asarray(cam.world_to_camera, "f4").T.tobytes())
            self.prog["u_proj"].write(np.asarray(cam.projection_gl(), "f4").T.tobytes())
            self.prog["u_bias"].value = 0.0
            self._draw_all(self.prog, False, bone_world)
            if self.settings.wireframe:
                ctx.wireframe = True
                ctx.line_width = float(max(1, s // 2))
                self.prog["u_bias"].value = WIRE_DEPTH_BIAS
                self._draw_all(self.prog, False, bone_world, wire=True)
                ctx.wireframe = False
            if self.skin is not None and self.settings.skin == "see-through":
                self.prog["u_bias"].value = 0.0
                self._draw_see_through_skin()
        raw = self.color_fbo.read(components=4, dtype="f4", viewport=(0, 0, Wt * s, Ht * s))
        hi = np.frombuffer(raw, dtype=np.float32).reshape(Ht * s, Wt * s, 4)[::-1]
        rgba = downsample(hi, s)
        # data pass (one sample per pixel centre)
        self.data_fbo.use()
        self.data_fbo.clear(0.0, 0.0, 0.0, 0.0, depth=1.0)
        for cam in cameras:
            x0, y0, w, h = cam.viewport
            self.data_fbo.viewport = (x0, Ht - y0 - h, w, h)
            self.dprog["u_view"].write(np.asarray(cam.world_to_camera, "f4").T.tobytes())
            self.dprog["u_proj"].write(np.asarray(cam.projection_gl(), "f4").T.tobytes())
            self.dprog["u_bias"].value = 0.0
            self._draw_all(self.dprog, True, bone_world)
        data = np.frombuffer(self.data_fbo.read(components=4, dtype="f4", attachment=0,
                                                viewport=(0, 0, Wt, Ht)),
                             dtype=np.float32).reshape(Ht, Wt, 4)[::-1]
        idf = np.frombuffer(self.data_fbo.read(components=1, dtype="f4", attachment=1,
                                               viewport=(0, 0, Wt, Ht)),
                            dtype=np.float32).reshape(Ht, Wt)[::-1]
        return FrameImages(frame=int(frame), rgba=rgba, depth=np.ascontiguousarray(data[..., 3]),
                           normals=np.ascontiguousarray(data[..., :3]),
                           ids=np.rint(idf).astype(np.uint32), cameras=tuple(cameras))

    def amodal(self, camera: Camera) -> np.ndarray:
        """(M, H, W) bool: each muscle's full extent seen by ``camera`` (a whole-image camera),
        occluders ignored, sampled at pixel centres; the muscles of the last :meth:`render`."""
        ctx = self.ctx
        check_same_process(ctx)
        W, H = self.settings.size
        if self._mask is None:
            prog = ctx.program(vertex_shader=_MASK_VERT, fragment_shader=_MASK_FRAG)
            texs = [ctx.texture((W, H), 4, dtype="f1") for _ in range(MASK_TARGETS)]
            fbo = ctx.framebuffer(texs)
            vaos = [ctx.vertex_array(prog, [(vpos, "3f", "in_pos")], index_buffer=vao.index_buffer,
                                     index_element_size=4) for vpos, _, vao, *_ in self.muscles]
            self._mask = (prog, texs, fbo, vaos)
        prog, texs, fbo, vaos = self._mask
        per = 4 * MASK_TARGETS
        out = np.zeros((len(vaos), H, W), dtype=bool)
        fbo.use()
        fbo.viewport = (0, 0, W, H)
        prog["u_view"].write(np.asarray(camera.world_to_camera, "f4").T.tobytes())
        prog["u_proj"].write(np.asarray(camera.projection_gl(), "f4").T.tobytes())
        ctx.enable_only(ctx.BLEND)
        ctx.blend_func = ctx.ONE, ctx.ONE
        ctx.blend_equation = ctx.MAX
        try:
            for start in range(0, len(vaos), per):
                fbo.clear(0.0, 0.0, 0.0, 0.0)
                for i in range(start, min(start + per, len(vaos))):
                    k = i - start
                    prog["u_target"].value = k // 4
                    prog["u_channel"].value = tuple(float(c == k % 4) for c in range(4))
                    vaos[i].render()
                for t in range((min(per, len(vaos) - start) + 3) // 4):
                    raw = fbo.read(components=4, dtype="f1", attachment=t, viewport=(0, 0, W, H))
                    m = np.frombuffer(raw, dtype=np.uint8).reshape(H, W, 4)[::-1] > 127  # (H, W, 4)
                    n = min(4, len(vaos) - start - 4 * t)
                    out[start + 4 * t:start + 4 * t + n] = np.moveaxis(m[..., :n], -1, 0)
        finally:
            ctx.blend_equation = ctx.FUNC_ADD
            ctx.enable_only(ctx.DEPTH_TEST)
        return out

    def frames(self, chunks: Iterable[FrameChunk], cameras: dict) -> Iterator[FrameImages]:
        """Render every frame of ``chunks`` (in order); ``cameras``: frame number -> its
        cameras (one per panel)."""
        for chunk in chunks:
            for c, f in enumerate(np.asarray(chunk.frames).tolist()):
                if f not in cameras:
                    raise ValueError(f"frame {f} is not in Scene.frames")
                bw = placed_plates(self.scene, chunk.bone_world[c]) if len(self.scene.bones) else None
                layers = [(p[c], n[c]) for p, n in chunk.layers]
                img = self.render(f, [p[c] for p in chunk.positions], [n[c] for n in chunk.normals], bw, cameras[f],
                                  layers)
                if self.skin is not None and self.settings.skin == "opaque":
                    img = replace(img, under=self.under(img, [(p[c], m.faces) for p, m in
                                                              zip(chunk.positions, self.scene.muscles)]))
                yield img

    def under(self, img: FrameImages, meshes: list) -> tuple[np.ndarray, np.ndarray]:
        """The muscle-under-skin pass of a frame drawn with an opaque skin, panel by panel
        (:func:`axdf_cli.render.under.under_skin`); ``meshes``: each muscle's (V, 3) world
        vertices and faces."""
        from axdf_cli.render.under import under_skin

        uid = np.zeros(img.ids.shape, np.uint16)
        depth = np.zeros(img.ids.shape, np.float32)
        for panel, K, cam in panels(img):
            uid[panel], depth[panel] = under_skin(img.depth[panel], img.ids[panel], skin_id(self.scene), K,
                                                  cam.world_to_camera, meshes)
        return uid, depth

    def parts(self, img: FrameImages, vertices: np.ndarray, faces: np.ndarray, face_part: np.ndarray) -> np.ndarray:
        """The body-part pass of a frame drawn with an opaque skin, panel by panel
        (:func:`axdf_cli.render.under.body_parts`); ``vertices``: the skin's (V, 3) world
        vertices that frame, ``faces`` its triangles, ``face_part`` (F,) each one's part."""
        from axdf_cli.render.under import body_parts

        out = np.zeros(img.ids.shape, np.uint16)
        for panel, K, cam in panels(img):
            out[panel] = body_parts(img.depth[panel], img.ids[panel], skin_id(self.scene), K, cam.world_to_camera,
                                    vertices, faces, face_part)
        return out

    def release(self) -> None:
        # bind the default framebuffer first: moderngl re-binds the framebuffer last used when it
        # makes one, and a deleted name there is GL_INVALID_OPERATION for the next renderer
        (self.ctx.screen or self.ctx.detect_framebuffer(0)).use()
        meshes = [obj for vpos, vnrm, vao, dvao, *_ in self.muscles for obj in (vao, dvao, vpos, vnrm)]
        meshes += [obj for _, vao, dvao, _ in self.bones for obj in (vao, dvao)]
        meshes += [obj for vpos, vnrm, vao, dvao, *_ in self.layers.values() for obj in (vao, dvao, vpos, vnrm)]
        for obj in (*meshes, *(self.skin or ()), self.color_fbo, self.data_fbo, self.color_tex, self.data_tex,
                    self.id_tex, self.prog, self.dprog):
            obj.release()
        if self._mask is not None:
            prog, texs, fbo, vaos = self._mask
            for obj in (*vaos, fbo, *texs, prog):
                obj.release()


def render_frames(ctx, scene: Scene, chunks: Iterable[FrameChunk], settings: RenderSettings,
                  cameras: list[list[Camera]] | None = None) -> Iterator[FrameImages]:
    """Render every frame of ``chunks`` (in order) with ``ctx``; yield :class:`FrameImages`."""
    if cameras is None:
        cameras = sequence_cameras(scene, settings)
    r = Renderer(ctx, scene, settings, len(cameras[0]) if cameras else 1)
    try:
        yield from r.frames(chunks, frame_cameras(scene, cameras))
    finally:
        r.release()


def frame_cameras(scene: Scene, cameras: list[list[Camera]]) -> dict:
    """Frame number -> its cameras (``cameras`` as :func:`sequence_cameras` gives them)."""
    return {int(f): cams for f, cams in zip(scene.frames, cameras)}
