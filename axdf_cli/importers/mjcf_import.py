"""``axdf import mjcf``: a MuJoCo model (+ a ``qpos`` motion) → the neutral import model.

:func:`read_import` reads and checks every input and fills an
:class:`~axdf_cli.importers.model.ImportedModel`, which
:func:`~axdf_cli.importers.emit.build_import` turns into the bytes of every output file; the
CLI writes them (atomically) only when all inputs were good.

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
  Its size follows the one belly law of every import (:func:`~axdf_cli.importers.emit.belly_doc`)
  from MuJoCo's own numbers (:func:`hill_numbers`).
- Bone meshes: the mesh geoms of a body, placed by the geom's frame (mesh ``scale``,
  ``refpos``, ``refquat`` applied as MuJoCo does), one PLY per body; ``max_faces`` decimates
  each (quadric edge collapse, ``fast-simplification``).
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from axdf_cli import tolerances as tol
from axdf_cli.errors import EnvironmentProblem, InputError, Mark
from axdf_cli.fileio.atomic import sha256_file
from axdf_cli.fileio.yamlio import NAME_ALLOWED, is_name
from axdf_cli.importers import emit
from axdf_cli.importers.mjcf import Coupling, Joint, MjcfModel, Muscle, load_mjcf, quat_matrix
from axdf_cli.importers.model import Bone, Coordinate, Dof, Hill, ImportedModel, Motion, Rules
from axdf_cli.importers.model import Muscle as ImportedMuscle
from axdf_cli.importers.qpos import WIDTH, QposJoint, qpos_coordinates, quat_to_euler, read_motion
from axdf_cli.importers.result import safe_name, yaml_number

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


def _const_translation(d: np.ndarray) -> Dof:
    n = float(np.linalg.norm(d))
    return Dof("translation", _clean(d / n), None, {"constant": n})


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
    own = P(np.trim_zeros(np.asarray(c.polycoef, dtype=np.float64), "b") if any(c.polycoef) else [0.0])
    if c.joint2 is None:
        return None, P([c.polycoef[0]])
    root, inner = coupling_polynomial(model, c.joint2, by, seen + (joint,))
    degree = own.degree() * inner.degree()
    if degree > tol.COUPLING_MAX_DEGREE:
        raise InputError(c.mark, f"joint {joint!r} follows a chain of couplings {' <- '.join((joint,) + _chain(c.joint2, by))}"
                         f" whose composed polynomial has degree {degree}",
                         f"chains whose polynomials compose to degree at most {tol.COUPLING_MAX_DEGREE} "
                         "(couple the joints to the chain's first joint directly)")
    composed = own(inner)
    if not np.all(np.isfinite(composed.coef)) or np.max(np.abs(composed.coef)) > tol.MAX_ABS_NUMBER:
        raise InputError(c.mark, f"joint {joint!r}: its chain of couplings composes to a polynomial with a "
                         f"coefficient of {float(np.max(np.abs(composed.coef))):g}",
                         f"coefficients within ±{tol.MAX_ABS_NUMBER:g} once the chain is composed")
    return root, composed


def _chain(joint: str, by: dict[str, Coupling]) -> tuple[str, ...]:
    """The joints a coupled ``joint`` follows, itself first (for messages; cycles are refused before)."""
    out = [joint]
    while joint in by and by[joint].joint2 is not None and len(out) <= len(by):
        joint = by[joint].joint2
        out.append(joint)
    return tuple(out)


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


def skeleton(model: MjcfModel, names: Names) -> tuple[list[Bone], list[Coordinate], list[QposJoint]]:
    """The bones (``world``, then a bone per body), the coordinates in qpos order, and the
    joints that are coordinates with their qpos indices (qpos order: the order of the
    coordinates and of the pose's values)."""
    by = {}
    for c in model.couplings:
        if c.joint1 in by:
            raise InputError(c.mark, f"joint {c.joint1!r} is coupled twice", "one joint equality per dependent joint")
        by[c.joint1] = c
    coords: dict[str, Coordinate] = {}
    rows: list[QposJoint] = []
    nq = 0  # the next joint's qpos index
    bones = [Bone("world")]
    for body in model.bodies:
        b = Bone(names("body", body.name), names("body", body.parent) if body.parent else "world", anchor_first=True)
        free = body.joints and body.joints[0].type == "free"
        if free:
            j = body.joints[0]
            jn = names("joint", j.name)
            euler = quat_to_euler(body.quat)
            for k, ax in enumerate("xyz"):
                c = f"{jn}_t{ax}"
                coords[c] = Coordinate(c, "translation", float(body.pos[k]))
                b.dofs.append(Dof("translation", _clean(np.eye(3)[k]), c))
            for k, ax in enumerate("xyz"):
                c = f"{jn}_r{ax}"
                coords[c] = Coordinate(c, "rotation", float(euler[k]))
                b.dofs.append(Dof("rotation", _clean(np.eye(3)[k]), c))
            rows.append(QposJoint(j.name, "free", nq, tuple(f"{jn}_{s}" for s in ("tx", "ty", "tz", "rx", "ry", "rz"))))
            nq += WIDTH["free"]
        else:
            b.offset = _clean(body.pos)
            b.orient = _clean(quat_to_euler(body.quat))
            anchor = np.zeros(3)
            for j in body.joints:
                jn = names("joint", j.name)
                if j.type in ("hinge", "ball") and np.any(j.pos != anchor):
                    b.dofs.append(_const_translation(j.pos - anchor))
                    anchor = j.pos.copy()
                if j.type == "ball":
                    for k, ax in enumerate("xyz"):
                        c = f"{jn}_r{ax}"
                        coords[c] = Coordinate(c, "rotation", 0.0)
                        b.dofs.append(Dof("rotation", _clean(np.eye(3)[k]), c))
                    rows.append(QposJoint(j.name, "ball", nq, tuple(f"{jn}_r{s}" for s in "xyz")))
                    nq += WIDTH["ball"]
                    continue
                dtype = "rotation" if j.type == "hinge" else "translation"
                coord, fn = dof_function(model, j, by)
                b.dofs.append(Dof(dtype, _clean(j.axis), names("joint", coord) if coord is not None else None, fn))
                if j.name not in by:
                    coords[jn] = _coordinate(j, jn, dtype)
                    rows.append(QposJoint(j.name, j.type, nq, (jn,)))
                nq += WIDTH[j.type]
            if np.any(anchor != 0):
                b.post_offset = _clean(anchor)
        bones.append(b)
    return bones, [coords[c] for r in rows for c in r.coords], rows


def _coordinate(j: Joint, name: str, dtype: str) -> Coordinate:
    """A hinge's or slide's coordinate in axdf units: its ref the default, its range when limited."""
    k = _unit(j)
    c = Coordinate(name, dtype, j.ref * k, (j.range[0] * k, j.range[1] * k) if j.range is not None else None)
    for key, values in (("default", [c.default]), ("range", list(c.range or []))):
        far = [v for v in values if abs(v) > tol.MAX_ABS_NUMBER]
        if far:
            unit = "degrees" if dtype == "rotation" else "m"
            raise InputError(j.mark, f"joint {j.name!r}: its {'ref' if key == 'default' else key} "
                             f"is {far[0]:g} {unit}", f"within ±{tol.MAX_ABS_NUMBER:g} {unit} "
                             "(what every axdf file holds)")
    return c


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


def geom_meshes(model: MjcfModel, max_faces: int, report: dict, edge: float = 0.0) -> dict[str, bytes]:
    """Body → binary PLY bytes: its mesh geoms in the body frame (``v_body = R_g (s ⊙ R_ref^T
    (v − refpos)) + p_g``, as MuJoCo places them), faces turned when the scale mirrors."""
    out = {}
    cache: dict[str, tuple] = {}
    rows = []
    for body in model.bodies:
        parts = []
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
                emit.check_vertices(v, asset.mark, f"mesh {asset.name!r} ({asset.file.name}, scaled)")
                if np.prod(np.sign(asset.scale)) < 0:
                    f = f[:, ::-1]
                n0 = len(f)
                v, f = decimate(v, f, face_budget(v, f, max_faces, edge))
                cache[asset.name] = (v, f)
                rows.append({"mesh": asset.name, "file": asset.file.name, "faces": int(n0), "kept": int(len(f))})
            v, f = cache[asset.name]
            parts.append((v @ quat_matrix(g.quat).T + g.pos, f))
            emit.check_vertices(parts[-1][0], g.mark, f"mesh geom {g.mesh!r} on body {body.name!r}")
        if parts:
            out[body.name] = emit.body_ply(parts, body.mark, f"the bone mesh of body {body.name!r}")
    report["meshes"] = rows
    return out


# ----------------------------------------------------------------------------- muscles


def hill_numbers(m: Muscle) -> tuple[Hill | None, float, list[str]]:
    """(Hill numbers, max isometric force N, notes) of a MuJoCo muscle; the Hill numbers None
    without a ``lengthrange`` (the emitter then takes FALLBACK_FIBRE_SHARE of the rest path). MuJoCo's muscle (Todorov's, ``mjs_setToMuscle``) has no fibre length of its own:
    its ``lengthrange`` [L_lo, L_hi] (actuator length = gear × tendon length) is what the
    normalized fibre length's ``range`` [r_lo, r_hi] spans, so L0 = (L_hi − L_lo) / (r_hi −
    r_lo) / gear and the tendon slack length LT = L_lo / gear − r_lo · L0. Force at the tendon:
    gear × force."""
    notes = []
    if m.lengthrange is not None:
        l0 = (m.lengthrange[1] - m.lengthrange[0]) / (m.range[1] - m.range[0]) / m.gear
        lt = max(m.lengthrange[0] / m.gear - m.range[0] * l0, 0.0)
    else:
        l0 = lt = None
        notes.append(f"no lengthrange (MuJoCo computes it when compiling): fibres {FALLBACK_FIBRE_SHARE:g} of the rest path")
    if m.force > 0:
        force = m.force * m.gear
    else:
        force = m.scale * m.gear
        notes.append(f"force {m.force:g} (MuJoCo's scale / acc0, known only to its compiler): {m.scale:g} N assumed")
        if not m.scale > 0:
            raise InputError(m.mark, f"muscle {m.name!r} has force {m.force:g} and scale {m.scale:g}: no positive force "
                             "to size its belly by", "a positive force, or a positive scale with force -1 (MuJoCo's "
                             "default)")
    return (Hill(force, l0, lt) if l0 is not None else None), force, notes


def tendon_paths(model: MjcfModel, names: Names, m: Muscle) -> tuple[list, list] | None:
    """A muscle's path points and wrap surfaces from its spatial tendon; None when it has a pulley."""
    from axdf_cli.model.paths import PathPoint, WrapSurface

    t = model.tendons[m.tendon]
    if any(it.kind == "pulley" for it in t.items):
        return None
    path, wraps, used = [], [], {}
    for it in t.items:
        if it.kind == "site":
            s = model.sites[it.name]
            path.append(PathPoint(names("body", s.body) if s.body != "world" else "world",
                                  tuple(float(x) for x in s.pos)))
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
        wraps.append(WrapSurface(wname, bone, MJ_SHAPES[g.type], (float(g.size[0]), 0.0, 0.0),
                                 tuple(float(x) for x in g.pos), tuple(_clean(quat_to_euler(g.quat))),
                                 range=(k, k + 1), side=side))
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


def motion_keys(rows: list[QposJoint], q: np.ndarray, source: str) -> dict[int, dict[str, float]]:
    """Frame → {coordinate: value} of a qpos motion (every coordinate at every frame)."""
    values = qpos_coordinates(rows, q, source)
    names = list(values)
    arr = np.stack([values[c] for c in names], axis=1) if names else np.zeros((len(q), 0))
    return {f: {c: float(arr[f, i]) for i, c in enumerate(names)} for f in range(len(q))}


# ----------------------------------------------------------------------------- all


# ----------------------------------------------------------------------------- the model

RULES = Rules("axdf import mjcf", probe_ranges=True, min_slenderness=MIN_REST_SLENDERNESS, shortfall=True,
              columns=("muscle", "sites", "wrap_geoms", "rest_path", "force", "pcsa", "fibres", "free_tendon",
                       "belly", "belly_d", "tendon_d", "slenderness"),
              fibre_words="optimal fibre length (MuJoCo: lengthrange / range)")


def read_import(model_path: Path | str, *, name: str | None = None, motion: Path | str | None = None,
                pose_name: str | None = None, fps: float | None = None, meshes: bool = True, max_faces: int = 0,
                mesh_edge: float = 0.0) -> ImportedModel:
    """``axdf import mjcf``: a MuJoCo model (+ a qpos motion) read and checked into the neutral
    model. ``fps`` overrides the motion's; ``max_faces`` (0: all) bounds each bone mesh,
    ``mesh_edge`` (m, 0: off) decimates it to about that edge length (:func:`face_budget`)."""
    model_path = Path(model_path)
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
    report: dict = {"source": {"model": model_path.name, "sha256": sha256_file(model_path), "model_name": model.name},
                    "tool": "axdf import mjcf", "skeleton": name}
    mesh_bytes = geom_meshes(model, max_faces, report, mesh_edge) if meshes else {}
    plys = {names("body", body): data for body, data in sorted(mesh_bytes.items())}
    bones, coords, rows = skeleton(model, names)
    inputs = [Path(x) for x in (model_path, motion) if x is not None]
    out = ImportedModel(name, f"Imported from {model_path.name} (MuJoCo model {model.name!r}) by `axdf import mjcf`.\n"
                              "Regenerate with the importer rather than editing by hand.",
                        bones, RULES, coords, plys, report=report, strip=inputs,
                        inputs=[model_path, *model.includes, *([Path(motion)] if motion is not None else [])],
                        assets=sorted({model.meshes[m["mesh"]].file for m in report.get("meshes", [])}),
                        refuse_at=Mark(str(model_path)), intro=_intro,
                        poses=f"the rest pose, {tol.AXIS_PROBE_POSES} seeded poses in the joints' ranges"
                              + (" and the motion's frames" if motion is not None else ""))
    skipped = []
    for m in model.muscles:
        mname = names("muscle", m.name or m.tendon)
        docs = tendon_paths(model, names, m)
        if docs is None:
            skipped.append({"kind": "muscle", "name": m.name, "where": str(m.mark),
                            "why": "its tendon branches at a pulley: not one path"})
            continue
        hill, force, notes = hill_numbers(m)
        out.warnings += [f"{m.mark}: muscle {m.name!r}: {n}" for n in notes]
        path, wraps = docs
        out.muscles.append(ImportedMuscle(
            mname, path, wraps, hill, f"{mname}: imported from {model_path.name} (MuJoCo {m.kind} on tendon "
                                      f"{m.tendon}) by `axdf import mjcf`.",
            {"type": m.kind, "tendon": m.tendon, "sidesites": sum(w.side is not None for w in wraps), "force": force,
             "lengthrange": m.lengthrange, "notes": notes}, fibre_share=FALLBACK_FIBRE_SHARE, force=force, mark=m.mark))
    if q is not None:
        out.motion = Motion(pname, fps, len(q), motion_keys(rows, q, str(motion)),
                            f"Imported from {Path(motion).name} by `axdf import mjcf`.", mark=Mark(str(motion)),
                            remedy="a shorter motion")
        report["motion"] = {"file": Path(motion).name, "sha256": sha256_file(Path(motion)), "frames": int(len(q)),
                            "fps": yaml_number(fps), "coupled_joints_ignored": emit.rounded(coupled_deviation(model, q))}
    out.ignored = model.ignored + skipped
    report["settings"] = {"specific_tension_Pa": emit.SPECIFIC_TENSION, "tendon_stress_Pa": emit.TENDON_STRESS,
                          "free_tendon_share": emit.FREE_TENDON_SHARE, "max_faces": max_faces, "mesh_edge_m": mesh_edge}

    def complete(r: dict) -> None:
        mrows = r["muscles"]
        r["counts"] = {"bodies": len(model.bodies), "joints": len(model.joints),
                       "coordinates": sum(len(x.coords) for x in rows), "couplings": len(model.couplings),
                       "muscles": len(mrows), "meshes": len(mesh_bytes),
                       "path_points": sum(x["path_points"] for x in mrows),
                       "wrap_surfaces": sum(len(x["wraps"]) for x in mrows),
                       "sidesites": sum(x["sidesites"] for x in mrows)}
        r["renamed"] = names.renamed

    out.complete = complete
    return out


def _intro(r: dict) -> list[str]:
    """IMPORT.md's opening of a MuJoCo import: source, counts, bone meshes, motion, renames."""
    c = r["counts"]
    lines = [f"Source: `{r['source']['model']}` (sha256 `{r['source']['sha256'][:16]}…`), "
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
    return lines
