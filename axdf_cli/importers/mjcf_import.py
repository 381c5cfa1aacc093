"""``axdf import mjcf``: a MuJoCo model (+ a ``qpos`` motion) → axdf files, in memory.

:func:`build_import` reads and checks every input first and returns an
:class:`~axdf_cli.importers.result.ImportResult` holding the bytes of every output file;
the CLI writes them (atomically) only when all inputs were good.

How MuJoCo maps to axdf (docs/FORMATS.md, "Imported MuJoCo models")
--------------------------------------------------------------------
- World: MuJoCo's world is Z-up in metres, as axdf's: the root bone ``world`` is the identity
  and every body keeps its own frame (bone = body, same name), so sites, geoms and meshes are
  copied unchanged.
- A body's ``pos``/``quat`` are its bone's ``offset``/``orient``. Its joints become DOFs in
  MuJoCo's order: a hinge rotates about its ``pos`` (MuJoCo's anchor): a constant translation
  to the anchor, the rotation, and the way back (consecutive anchors are joined by one
  constant translation; the last anchor is the bone's ``post_offset``); a slide translates
  along its axis; a ball is three rotations X, Y, Z about its anchor; a free joint (in a child
  of the world) is three translations and three rotations X, Y, Z in the world.
- Coordinates: a hinge or slide joint is the coordinate of its own name (degrees, metres),
  its default MuJoCo's ``ref`` (qpos0), its range the joint's when limited; MuJoCo turns a
  hinge by qpos − ref, so a non-zero ``ref`` gives the DOF ``{linear: [1, -ref]}``. A ball
  joint J gives ``J_rx, J_ry, J_rz``, a free joint ``J_tx, J_ty, J_tz, J_rx, J_ry, J_rz``
  (defaults: the body's pose, as qpos0). A joint coupled by ``<equality><joint>`` is no
  coordinate: its DOF follows the polynomial of the joint it depends on (composed through
  chains), rewritten in axdf units (:func:`coupling_polynomial`).
- Quaternions (ball and free joints in a motion) become intrinsic X-Y-Z Euler angles in
  degrees, the middle angle within ±90° (:func:`~axdf_cli.importers.qpos.quat_to_euler`), each unwrapped over the
  frames (no jump of 360°); X-Y-Z rotations of those angles give back the same rotation, so
  ``euler_to_quat(quat_to_euler(q)) = ±q`` (tested).
- Muscles: every muscle actuator on a spatial tendon becomes a path muscle of the same name:
  its sites are the path points, each wrap geom a ``mujoco_sphere`` or ``mujoco_cylinder``
  surface with its ``side`` point (the sidesite) and ``range`` the two sites around it.
  Its size follows the belly law of OpenSim imports (:func:`~axdf_cli.importers.emit.belly_doc`)
  from MuJoCo's own numbers (:func:`hill_numbers`).
- Bone meshes: the mesh geoms of a body, placed by the geom's frame (mesh ``scale``,
  ``refpos``, ``refquat`` applied as MuJoCo does), one PLY per body; ``max_faces`` decimates
  each (quadric edge collapse, ``fast-simplification``).
"""
from __future__ import annotations

import json
import math
import re
from pathlib import Path

import numpy as np

from axdf_cli import tolerances as tol
from axdf_cli.errors import EnvironmentProblem, InputError, Mark
from axdf_cli.fileio.atomic import sha256_file
from axdf_cli.fileio.outputs import UniqueFiles
from axdf_cli.fileio.yamlio import NAME_ALLOWED, is_name
from axdf_cli.formats.ply import PlyWriter
from axdf_cli.importers import emit
from axdf_cli.importers.mjcf import Body, Coupling, Joint, MjcfModel, Muscle, load_mjcf, quat_matrix
from axdf_cli.importers.qpos import WIDTH, QposJoint, qpos_coordinates, quat_to_euler, read_motion
from axdf_cli.importers.result import (ImportResult, axis_markdown, belly_markdown, relative_ref, safe_name,
                                      strip_dirs, yaml_number)
from axdf_cli.specs import RefPolicy, parse_skeleton_text

DEG = 180.0 / math.pi
#: Without a ``lengthrange`` (MuJoCo computes one when it compiles the model), the optimal
#: fibre length is this share of the rest path and the tendon slack length the rest of it.
FALLBACK_FIBRE_SHARE = 0.5
#: (Without a positive ``force``, MuJoCo's default -1 meaning scale / acc0, which only MuJoCo's
#: compiler knows, the max isometric force is ``scale`` newtons: :func:`hill_numbers`.)
#: MuJoCo's wrap geoms → axdf wrap shapes.
MJ_SHAPES = {"sphere": "mujoco_sphere", "cylinder": "mujoco_cylinder"}
#: Bellies squatter than this at rest are thinned (emit.belly_doc): MuJoCo's models carry big
#: forces on short paths (pronator quadratus, anconeus, the multifidi's short slips), and a
#: belly squats further as its muscle shortens in motion; the library's floor is 1.2.
MIN_REST_SLENDERNESS = 1.5


# ----------------------------------------------------------------------------- names


class Names:
    """MJCF names → axdf names (``[A-Za-z0-9_.-]``, at most 200 characters, unique per kind)."""

    def __init__(self):
        self.maps: dict[str, dict[str, str]] = {}
        self.renamed: list[dict] = []

    def __call__(self, kind: str, name: str) -> str:
        m = self.maps.setdefault(kind, {})
        if name in m:
            return m[name]
        new = name if is_name(name) else (safe_name(name)[:200] or "x")
        base, k = new, 2
        while new in m.values():
            new = f"{base}_{k}"
            k += 1
        if new != name:
            self.renamed.append({"kind": kind, "mjcf": name, "axdf": new})
        m[name] = new
        return new


# ----------------------------------------------------------------------------- skeleton


def _clean(v) -> list[float]:
    return [float(x) + 0.0 for x in v]


def _const_translation(d: np.ndarray) -> dict:
    n = float(np.linalg.norm(d))
    return {"type": "translation", "axis": _clean(d / n), "function": {"constant": n}}


def _poly_function(p: np.polynomial.Polynomial) -> dict | None:
    """A numpy polynomial as an axdf function (None: the identity)."""
    c = np.trim_zeros(np.asarray(p.coef, dtype=np.float64), "b")
    if len(c) == 0:
        return {"constant": 0.0}
    if len(c) == 1:
        return {"constant": float(c[0])}
    if len(c) == 2:
        if c[0] == 0.0 and c[1] == 1.0:
            return None
        return {"linear": [float(c[1]), float(c[0])]}
    return {"polynomial": [float(x) for x in c]}


def _unit(j: Joint) -> float:
    """axdf units per MuJoCo unit of a hinge (degrees per radian) or slide (1)."""
    return DEG if j.type == "hinge" else 1.0


def coupling_polynomial(model: MjcfModel, joint: str, by: dict[str, Coupling],
                        seen: tuple = ()) -> tuple[str | None, np.polynomial.Polynomial]:
    """The independent joint that ``joint`` follows and the polynomial, in MuJoCo units, of
    ``joint`` − its ref in terms of (that joint − its ref); the joint itself and x when it is
    independent. Chains compose; a coupling to nothing is a constant (joint None)."""
    P = np.polynomial.Polynomial
    if joint not in by:
        return joint, P([0.0, 1.0])
    if joint in seen:
        raise InputError(by[joint].mark, f"joint couplings form a cycle through {joint!r}", "couplings without a cycle")
    c = by[joint]
    own = P(c.polycoef)
    if c.joint2 is None:
        return None, P([c.polycoef[0]])
    root, inner = coupling_polynomial(model, c.joint2, by, seen + (joint,))
    return root, own(inner)


def dof_function(model: MjcfModel, j: Joint, by: dict[str, Coupling]) -> tuple[str | None, dict | None]:
    """The coordinate driving hinge/slide ``j``'s DOF and its function in axdf units (None:
    the coordinate itself): DOF = k_j · P(x / k_r − ref_r), x the coordinate of the
    independent joint r (axdf units), P the composed coupling (MuJoCo units)."""
    P = np.polynomial.Polynomial
    root, poly = coupling_polynomial(model, j.name, by)
    if root is None:
        return None, {"constant": float(_unit(j) * poly.coef[0])}
    r = model.joints[root]
    f = _unit(j) * poly(P([-r.ref, 1.0 / _unit(r)]))
    return root, _poly_function(f)


def skeleton_doc(model: MjcfModel, name: str, names: Names, meshes: dict[str, str]) -> tuple[dict, list[QposJoint]]:
    """The skeleton YAML document and the joints that are its coordinates, with their qpos
    indices (qpos order: the order of the coordinates and of the pose's values). ``meshes``:
    body → mesh path relative to the skeleton file."""
    by = {}
    for c in model.couplings:
        if c.joint1 in by:
            raise InputError(c.mark, f"joint {c.joint1!r} is coupled twice", "one joint equality per dependent joint")
        by[c.joint1] = c
    coords: dict[str, dict] = {}
    rows: list[QposJoint] = []
    nq = 0  # the next joint's qpos index
    bones: list[dict] = [{"name": "world"}]
    if "world" in meshes:
        bones[0]["mesh"] = meshes["world"]
    for body in model.bodies:
        bname = names("body", body.name)
        b: dict = {"name": bname, "parent": names("body", body.parent) if body.parent else "world"}
        dofs: list[dict] = []
        free = body.joints and body.joints[0].type == "free"
        if free:
            j = body.joints[0]
            jn = names("joint", j.name)
            euler = quat_to_euler(body.quat)
            for k, ax in enumerate("xyz"):
                c = f"{jn}_t{ax}"
                coords[c] = {"type": "translation", "default": float(body.pos[k])}
                dofs.append({"coord": c, "type": "translation", "axis": _clean(np.eye(3)[k])})
            for k, ax in enumerate("xyz"):
                c = f"{jn}_r{ax}"
                coords[c] = {"type": "rotation", "default": float(euler[k])}
                dofs.append({"coord": c, "type": "rotation", "axis": _clean(np.eye(3)[k])})
            rows.append(QposJoint(j.name, "free", nq, tuple(f"{jn}_{s}" for s in ("tx", "ty", "tz", "rx", "ry", "rz"))))
            nq += WIDTH["free"]
        else:
            b["offset"] = _clean(body.pos)
            b["orient"] = _clean(quat_to_euler(body.quat))
            anchor = np.zeros(3)
            for j in body.joints:
                jn = names("joint", j.name)
                if j.type in ("hinge", "ball") and np.any(j.pos != anchor):
                    dofs.append(_const_translation(j.pos - anchor))
                    anchor = j.pos.copy()
                if j.type == "ball":
                    for k, ax in enumerate("xyz"):
                        c = f"{jn}_r{ax}"
                        coords[c] = {"type": "rotation", "default": 0.0}
                        dofs.append({"coord": c, "type": "rotation", "axis": _clean(np.eye(3)[k])})
                    rows.append(QposJoint(j.name, "ball", nq, tuple(f"{jn}_r{s}" for s in "xyz")))
                    nq += WIDTH["ball"]
                    continue
                dtype = "rotation" if j.type == "hinge" else "translation"
                coord, fn = dof_function(model, j, by)
                d: dict = {}
                if coord is not None:
                    d["coord"] = names("joint", coord)
                d["type"] = dtype
                d["axis"] = _clean(j.axis)
                if fn is not None:
                    d["function"] = fn
                dofs.append(d)
                if j.name not in by:
                    k = _unit(j)
                    cd = {"type": dtype, "default": j.ref * k}
                    if j.range is not None:
                        cd["range"] = [j.range[0] * k, j.range[1] * k]
                    for key in ("default", "range"):
                        far = [v for v in np.atleast_1d(cd.get(key, [])) if abs(v) > tol.MAX_ABS_NUMBER]
                        if far:
                            unit = "degrees" if dtype == "rotation" else "m"
                            raise InputError(j.mark, f"joint {j.name!r}: its {'ref' if key == 'default' else key} "
                                             f"is {far[0]:g} {unit}", f"within ±{tol.MAX_ABS_NUMBER:g} {unit} "
                                             "(what every axdf file holds)")
                    coords[jn] = cd
                    rows.append(QposJoint(j.name, j.type, nq, (jn,)))
                nq += WIDTH[j.type]
            if np.any(anchor != 0):
                b["post_offset"] = _clean(anchor)
        if dofs:
            b["dofs"] = dofs
        if body.name in meshes:
            b["mesh"] = meshes[body.name]
        bones.append(b)
    # coordinates in qpos order
    doc = {"skeleton": name, "coordinates": {c: coords[c] for r in rows for c in r.coords}, "bones": bones}
    if not doc["coordinates"]:
        del doc["coordinates"]
    return doc, rows


# ----------------------------------------------------------------------------- meshes


def _read_mesh(path: Path, mark: Mark) -> tuple[np.ndarray, np.ndarray]:
    import trimesh

    if not path.is_file():
        raise InputError(mark, f"mesh file {path.name!r} not found", "a file relative to the compiler's meshdir")
    try:
        m = trimesh.load(str(path), force="mesh", process=False)
    except Exception as e:  # trimesh raises many kinds on a malformed file
        raise InputError(mark, f"mesh file {path.name!r} cannot be read ({type(e).__name__}: {e})",
                         "an STL, OBJ or PLY triangle mesh") from None
    v = np.asarray(m.vertices, dtype=np.float64)
    f = np.asarray(m.faces, dtype=np.int64)
    if len(v) == 0 or len(f) == 0 or not np.all(np.isfinite(v)):
        raise InputError(mark, f"mesh file {path.name!r} holds no triangles or a non-finite vertex",
                         "a triangle mesh with finite vertices")
    return v, f


#: Decimated meshes keep at least this many triangles (a carpal bone stays a closed shape).
MIN_FACES = 200


def face_budget(v: np.ndarray, f: np.ndarray, max_faces: int, edge: float) -> int:
    """Triangles to keep (0: all): at most ``max_faces`` (0: no cap), and with ``edge`` > 0 about
    what equilateral triangles of that edge (m) need to tile the mesh's area, at least MIN_FACES."""
    n = len(f)
    if edge > 0:
        tri = v[f]
        # area[t] = |(b - a) x (c - a)| / 2
        area = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1).sum()
        n = min(n, max(MIN_FACES, int(area / (math.sqrt(3) / 4 * edge * edge))))
    if max_faces > 0:
        n = min(n, max_faces)
    return 0 if n >= len(f) else n


def decimate(v: np.ndarray, f: np.ndarray, max_faces: int) -> tuple[np.ndarray, np.ndarray]:
    """At most ``max_faces`` triangles: quadric edge collapse (fast-simplification, the
    Fast-Quadric-Mesh-Simplification algorithm); meshes already small are kept."""
    if max_faces <= 0 or len(f) <= max_faces:
        return v, f
    try:
        import fast_simplification
    except ImportError:
        raise EnvironmentProblem("decimating bone meshes needs fast-simplification",
                                 "pip install fast-simplification (or give --max-faces 0)") from None
    pv, pf = fast_simplification.simplify(v.astype(np.float32), f.astype(np.int32), 1.0 - max_faces / len(f))
    return np.asarray(pv, dtype=np.float64), np.asarray(pf, dtype=np.int64)


def body_meshes(model: MjcfModel, max_faces: int, report: dict, edge: float = 0.0) -> dict[str, bytes]:
    """Body → binary PLY bytes: its mesh geoms in the body frame (``v_body = R_g (s ⊙ R_ref^T
    (v − refpos)) + p_g``, as MuJoCo places them), faces turned when the scale mirrors."""
    out = {}
    cache: dict[str, tuple] = {}
    rows = []
    for body in model.bodies:
        vs, ts, base = [], [], 0
        for g in body.geoms:
            if g.type != "mesh" or g.mesh is None:
                continue
            asset = model.meshes.get(g.mesh)
            if asset is None:
                raise InputError(g.mark, f"geom names unknown mesh {g.mesh!r}", "a <mesh> of the <asset> section")
            if asset.name not in cache:
                v, f = _read_mesh(asset.file, asset.mark)
                v = (v - asset.refpos) @ quat_matrix(asset.refquat)  # R^T (v - refpos), row vectors
                v = v * asset.scale
                if np.prod(np.sign(asset.scale)) < 0:
                    f = f[:, ::-1]
                n0 = len(f)
                v, f = decimate(v, f, face_budget(v, f, max_faces, edge))
                cache[asset.name] = (v, f)
                rows.append({"mesh": asset.name, "file": asset.file.name, "faces": int(n0), "kept": int(len(f))})
            v, f = cache[asset.name]
            vs.append(v @ quat_matrix(g.quat).T + g.pos)
            ts.append(f + base)
            base += len(v)
        if vs:
            out[body.name] = PlyWriter(np.concatenate(ts)).encode(np.concatenate(vs))
    report["meshes"] = rows
    return out


# ----------------------------------------------------------------------------- muscles


def hill_numbers(m: Muscle, rest_length: float) -> tuple[float, float, float, list[str]]:
    """(max isometric force N, optimal fibre length m, tendon slack length m, notes) of a MuJoCo
    muscle. MuJoCo's muscle (Todorov's, ``mjs_setToMuscle``) has no fibre length of its own:
    its ``lengthrange`` [L_lo, L_hi] (actuator length = gear × tendon length) is what the
    normalized fibre length's ``range`` [r_lo, r_hi] spans, so L0 = (L_hi − L_lo) / (r_hi −
    r_lo) / gear and the tendon slack length LT = L_lo / gear − r_lo · L0. Force at the tendon:
    gear × force."""
    notes = []
    if m.lengthrange is not None:
        l0 = (m.lengthrange[1] - m.lengthrange[0]) / (m.range[1] - m.range[0]) / m.gear
        lt = max(m.lengthrange[0] / m.gear - m.range[0] * l0, 0.0)
    else:
        l0 = FALLBACK_FIBRE_SHARE * rest_length
        lt = rest_length - l0
        notes.append(f"no lengthrange (MuJoCo computes it when compiling): fibres {FALLBACK_FIBRE_SHARE:g} of the rest path")
    if m.force > 0:
        force = m.force * m.gear
    else:
        force = m.scale * m.gear
        notes.append(f"force {m.force:g} (MuJoCo's scale / acc0, known only to its compiler): {m.scale:g} N assumed")
    return force, l0, lt, notes


def tendon_paths(model: MjcfModel, names: Names, m: Muscle) -> tuple[list, list] | None:
    """A muscle's path and wrap documents from its spatial tendon; None when it has a pulley."""
    from axdf_cli.model.paths import PathPoint, WrapSurface

    t = model.tendons[m.tendon]
    if any(it.kind == "pulley" for it in t.items):
        return None
    path, wraps, used = [], [], {}
    for it in t.items:
        if it.kind == "site":
            s = model.sites[it.name]
            path.append(emit.point_doc(PathPoint(names("body", s.body) if s.body != "world" else "world",
                                                 tuple(float(x) for x in s.pos))))
            continue
        g = model.geoms[it.name]
        gname = names("geom", it.name)
        used[gname] = used.get(gname, 0) + 1
        wname = gname if used[gname] == 1 else f"{gname}_{used[gname]}"
        side = None
        if it.sidesite is not None:
            s = model.sites[it.sidesite]
            side = (names("body", s.body) if s.body != "world" else "world", tuple(float(x) for x in s.pos))
        k = len(path)  # the site before the geom is path point k (1-based)
        bone = names("body", g.body) if g.body != "world" else "world"
        wraps.append(emit.wrap_doc(WrapSurface(wname, bone, MJ_SHAPES[g.type], (float(g.size[0]), 0.0, 0.0),
                                               tuple(float(x) for x in g.pos), tuple(_clean(quat_to_euler(g.quat))),
                                               range=(k, k + 1), side=side)))
    return path, wraps


# ----------------------------------------------------------------------------- motion


def qpos_layout(model: MjcfModel) -> dict[str, int]:
    """Joint → its first qpos index (MuJoCo's order: joints as the bodies list them)."""
    out, k = {}, 0
    for body in model.bodies:
        for j in body.joints:
            out[j.name] = k
            k += {"free": 7, "ball": 4}.get(j.type, 1)
    out["__nq__"] = k
    return out


def coupled_deviation(model: MjcfModel, q: np.ndarray) -> dict[str, float]:
    """Per coupled joint, the largest |qpos − its polynomial of qpos| over the motion (MuJoCo units)."""
    adr = qpos_layout(model)
    by = {c.joint1: c for c in model.couplings}
    out = {}
    for name in by:
        root, poly = coupling_polynomial(model, name, by)
        j = model.joints[name]
        x = q[:, adr[root]] - model.joints[root].ref if root is not None else np.zeros(len(q))
        out[name] = float(np.max(np.abs(q[:, adr[name]] - j.ref - poly(x))))
    return out


def pose_doc(rows: list[QposJoint], q: np.ndarray, fps: float, pose_name: str, skeleton_ref: str,
             source: str) -> dict:
    values = qpos_coordinates(rows, q, source)
    names = list(values)
    arr = np.stack([values[c] for c in names], axis=1) if names else np.zeros((len(q), 0))
    keys = {f: {c: float(arr[f, i]) for i, c in enumerate(names)} for f in range(len(q))}
    return {"pose": pose_name, "skeleton": skeleton_ref, "fps": yaml_number(fps), "frames": [0, len(q) - 1],
            "interpolation": "linear", "keys": keys}


# ----------------------------------------------------------------------------- all


def build_import(model_path: Path | str, out_dir: Path | str, *, name: str | None = None,
                 motion: Path | str | None = None, skeleton_out: Path | str | None = None,
                 muscles_out: Path | str | None = None, pose_out: Path | str | None = None,
                 meshes_out: Path | str | None = None, pose_name: str | None = None, fps: float | None = None,
                 meshes: bool = True, max_faces: int = 0, mesh_edge: float = 0.0,
                 palette: str = "anatomical") -> ImportResult:
    """Read ``model_path`` (+ a qpos motion) and build every output file's bytes.

    Layout as ``axdf import osim``'s: ``skeletons/NAME.yaml``, ``skeletons/meshes/NAME/*.ply``,
    ``muscles/MUSCLE.yaml``, ``POSE.yaml`` (with a motion), ``import_report.json``, ``IMPORT.md``.
    ``fps`` overrides the motion's; ``max_faces`` (0: all) bounds each bone mesh, ``mesh_edge``
    (m, 0: off) decimates it to about that edge length (:func:`face_budget`).
    """
    model_path = Path(model_path)
    out_dir = Path(out_dir)
    model = load_mjcf(model_path)
    name = name or safe_name(model.name)
    pname = pose_name or (safe_name(Path(motion).stem) if motion is not None else None)
    for what, v in (("--name", name), ("--pose-name", pname)):
        if v is not None and not is_name(v):
            raise InputError(None, f"{what} {v!r}", NAME_ALLOWED)
    names = Names()
    names("body", "world")
    q = None
    if motion is not None:
        q, motion_fps = read_motion(Path(motion), qpos_layout(model)["__nq__"])
        fps = fps or motion_fps

    skel_path = Path(skeleton_out) if skeleton_out else out_dir / "skeletons" / f"{name}.yaml"
    mesh_dir = Path(meshes_out) if meshes_out else skel_path.parent / "meshes" / name
    mus_dir = Path(muscles_out) if muscles_out else out_dir / "muscles"
    pose_path = (Path(pose_out) if pose_out else out_dir / f"{pname}.yaml") if motion is not None else None

    warnings: list[str] = []
    report: dict = {"source": {"model": model_path.name, "sha256": sha256_file(model_path), "model_name": model.name},
                    "tool": "axdf import mjcf", "skeleton": name}
    files: dict[str, bytes] = UniqueFiles()  # a path twice: exit 2, never one file lost
    mesh_bytes = body_meshes(model, max_faces, report, mesh_edge) if meshes else {}
    mesh_refs = {}
    for body, data in sorted(mesh_bytes.items()):
        p = mesh_dir / f"{names('body', body)}.ply"
        files[str(p)] = data
        mesh_refs[body] = relative_ref(p, skel_path.parent)
    sdoc, rows = skeleton_doc(model, name, names, mesh_refs)
    header = (f"Imported from {model_path.name} (MuJoCo model {model.name!r}) by `axdf import mjcf`.\n"
              "Regenerate with the importer rather than editing by hand.")
    text = emit.dump_yaml(sdoc, header)
    files[str(skel_path)] = text.encode()
    try:  # the skeleton as axdf will read it back (its meshes are files this import writes)
        skel = parse_skeleton_text(text, skel_path, RefPolicy(allow_outside=True))
    except InputError as e:  # a limit of the file format that the model's numbers exceed
        raise InputError(Mark(str(model_path)), f"the skeleton {skel_path.name} would not pass axdf validate ({e})",
                         "numbers and names within what axdf files hold") from None
    world = emit.rest_world(skel)

    mrows, skipped = [], []
    motion_q = None
    if q is not None:  # the motion's coordinates (F, C), as the pose will give them
        motion_q = np.tile(skel.rest_coordinates(), (len(q), 1))
        for c, v in qpos_coordinates(rows, q, str(motion)).items():
            motion_q[:, skel.coord_index[c]] = v
        motion_q = skel.couple(motion_q)
    probe = probe_poses(skel, motion_q)
    for m in model.muscles:
        mname = names("muscle", m.name or m.tendon)
        docs = tendon_paths(model, names, m)
        if docs is None:
            skipped.append({"kind": "muscle", "name": m.name, "where": str(m.mark),
                            "why": "its tendon branches at a pulley: not one path"})
            continue
        path, wraps = docs
        rest = _rest_length(mname, path, wraps, skel, world)
        force, l0, lt, notes = hill_numbers(m, rest)
        for n in notes:
            warnings.append(f"{m.mark}: muscle {m.name!r}: {n}")
        axis = emit.axis_points_for(mname, path, wraps, skel, probe)
        doc, row = emit.belly_doc(mname, path, wraps, force, l0, lt, 0.0, skel, world, palette,
                                  axis.n if axis.raised else 0, MIN_REST_SLENDERNESS)
        row.update({"type": m.kind, "tendon": m.tendon, "path_points": len(path), "wraps": [w["name"] for w in wraps],
                    "sidesites": sum("side" in w for w in wraps), "force": force, "lengthrange": m.lengthrange,
                    "notes": notes, "axis_shortfall": axis.error})
        if axis.raised:
            row["axis_points_raised"] = axis.row()
        mrows.append(emit.rounded(row))
        files[str(mus_dir / f"{mname}.yaml")] = emit.dump_yaml(
            doc, f"{mname}: imported from {model_path.name} (MuJoCo {m.kind} on tendon {m.tendon}) "
                 "by `axdf import mjcf`.").encode()
    report["muscles"] = mrows
    if q is not None:
        pdoc = pose_doc(rows, q, fps, pname, relative_ref(skel_path, pose_path.parent), str(motion))
        text = emit.dump_yaml(pdoc, f"Imported from {Path(motion).name} by `axdf import mjcf`.").encode()
        if len(text) > tol.YAML_MAX_BYTES:
            raise InputError(Mark(str(motion)), f"the pose would be {len(text)} bytes ({len(q)} frames)",
                             f"axdf reads YAML files up to {tol.YAML_MAX_BYTES} bytes; a shorter motion")
        files[str(pose_path)] = text
        dev = coupled_deviation(model, q)
        report["motion"] = {"file": Path(motion).name, "sha256": sha256_file(Path(motion)), "frames": int(len(q)),
                            "fps": yaml_number(fps), "coupled_joints_ignored": emit.rounded(dev)}
    report["counts"] = {"bodies": len(model.bodies), "joints": len(model.joints),
                        "coordinates": sum(len(r.coords) for r in rows), "couplings": len(model.couplings),
                        "muscles": len(mrows), "meshes": len(mesh_bytes),
                        "path_points": sum(r["path_points"] for r in mrows),
                        "wrap_surfaces": sum(len(r["wraps"]) for r in mrows),
                        "sidesites": sum(r["sidesites"] for r in mrows)}
    inputs = [Path(x) for x in (model_path, motion) if x is not None]
    read = [model_path, *model.includes, *([Path(motion)] if motion is not None else [])]
    assets = sorted({model.meshes[m["mesh"]].file for m in report.get("meshes", [])})
    report["ignored"] = [dict(i, where=strip_dirs(i["where"], inputs)) for i in model.ignored + skipped]
    report["warnings"] = [strip_dirs(w, inputs) for w in warnings]
    report["renamed"] = names.renamed
    report["settings"] = {"specific_tension_Pa": emit.SPECIFIC_TENSION, "tendon_stress_Pa": emit.TENDON_STRESS,
                          "free_tendon_share": emit.FREE_TENDON_SHARE, "palette": palette, "max_faces": max_faces,
                          "mesh_edge_m": mesh_edge}
    report["files"] = sorted(relative_ref(Path(p), out_dir) for p in files)
    files[str(out_dir / "import_report.json")] = (json.dumps(report, indent=1, sort_keys=True) + "\n").encode()
    files[str(out_dir / "IMPORT.md")] = import_markdown(report).encode()
    return ImportResult(files, report, warnings, None, read, assets,
                        layout={"muscles": mus_dir, "skeleton": skel_path, "pose": pose_path})


def probe_poses(skel, motion_q: np.ndarray | None = None) -> np.ndarray:
    """Coordinates (P, C) of the poses the axes are measured on (:func:`emit.axis_points_for`):
    the rest pose, AXIS_PROBE_POSES poses with every ranged coordinate uniform in its range
    (seeded: the same poses every import), and the imported motion's frames ``motion_q``
    (F, C) as an OpenSim import measures them (:func:`emit.motion_poses`)."""
    rng = np.random.default_rng(tol.AXIS_PROBE_SEED)
    q = np.tile(skel.rest_coordinates(), (tol.AXIS_PROBE_POSES + 1, 1))
    for i, c in enumerate(skel.coordinates):
        if c.range is not None:
            q[1:, i] = rng.uniform(c.range[0], c.range[1], size=tol.AXIS_PROBE_POSES)
    q = skel.couple(q)
    return q if motion_q is None else np.concatenate([q, emit.motion_poses(skel, motion_q)[1:]])


def _rest_length(name: str, path: list, wraps: list, skel, world) -> float:
    from axdf_cli.importers.emit import rest_path

    return rest_path(name, path, wraps, skel, world)[1]


def import_markdown(r: dict) -> str:
    c = r["counts"]
    lines = [f"# Import of {r['source']['model']} (`{r['skeleton']}`)", "",
             f"Source: `{r['source']['model']}` (sha256 `{r['source']['sha256'][:16]}…`), "
             f"MuJoCo model `{r['source']['model_name']}`, by `axdf import mjcf`.", "",
             f"- bodies {c['bodies']}, joints {c['joints']} ({c['couplings']} coupled by joint equalities), "
             f"coordinates {c['coordinates']}, bone meshes {c['meshes']}",
             f"- muscles {c['muscles']} from {c['path_points']} sites and {c['wrap_surfaces']} wrap geoms "
             f"({c['sidesites']} with a sidesite), wrapped every frame by MuJoCo's rules", ""]
    if r.get("meshes"):
        n0 = sum(m["faces"] for m in r["meshes"])
        n1 = sum(m["kept"] for m in r["meshes"])
        lines += [f"Bone meshes: {len(r['meshes'])} mesh files, {n0} triangles → {n1} kept"
                  + (f" (at most {r['settings']['max_faces']} per mesh)" if r["settings"]["max_faces"] else "")
                  + (f", decimated to edges of about {r['settings']['mesh_edge_m'] * 1000:g} mm"
                     if r["settings"]["mesh_edge_m"] else "") + " (quadric edge collapse).", ""]
    if "motion" in r:
        mo = r["motion"]
        dev = mo["coupled_joints_ignored"]
        lines += [f"Motion: `{mo['file']}`, {mo['frames']} frames at {mo['fps']} fps; coupled joints follow their "
                  f"polynomials (the motion's own values for them differ by at most "
                  f"{max(dev.values()) if dev else 0:.3g} in qpos units).", ""]
    if r["renamed"]:
        lines += ["Renamed (axdf names use letters, digits, '_', '.', '-'): "
                  + ", ".join(f"{x['kind']} `{x['mjcf']}` → `{x['axdf']}`" for x in r["renamed"]) + ".", ""]
    lines += axis_markdown(r, f"the rest pose, {tol.AXIS_PROBE_POSES} seeded poses in the joints' ranges"
                              + (" and the motion's frames" if "motion" in r else ""))
    lines += ["## Warnings", ""] + ([f"- {w}" for w in r["warnings"]] or ["- none"]) + [""]
    lines += ["## Not imported", "", "| kind | name | where | why |", "|---|---|---|---|"]
    lines += [f"| {i['kind']} | {i['name']} | {i['where']} | {i['why']} |" for i in r["ignored"]] or \
        ["| – | – | – | nothing |"]
    lines += belly_markdown_mjcf(r) if r["muscles"] else ["", "## Bellies", "", "No muscles."]
    lines += ["", "## Muscles", "", "| muscle | sites | wrap geoms | rest path (cm) | force (N) | PCSA (cm²) | "
              "fibres (cm) | free tendon (cm) | belly (cm) | belly Ø (mm) | tendon Ø (mm) | slenderness |",
              "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for m in r["muscles"]:
        lines.append(f"| {m['muscle']} | {m['path_points']} | {len(m['wraps'])} | {m['rest_path_length'] * 100:.1f} | "
                     f"{m['force']:.0f} | {m['pcsa_m2'] * 1e4:.2f} | {m['optimal_fiber_length'] * 100:.1f} | "
                     f"{m['free_tendon'] * 100:.1f} | {m['belly_length'] * 100:.1f} | {m['belly_radius'] * 2e3:.1f} | "
                     f"{m['tendon_radius'] * 2e3:.1f} | {m['slenderness']:.2f} |")
    return "\n".join(lines) + "\n"


def belly_markdown_mjcf(r: dict) -> list[str]:
    """The "Bellies" section, with MuJoCo's numbers in the law's words."""
    lines = belly_markdown(r)
    return [re.sub(r"optimal fibre length", "optimal fibre length (MuJoCo: lengthrange / range)", x, count=1)
            for x in lines]
