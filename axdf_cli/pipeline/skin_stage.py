"""The skin stage (scope FRAME, after contact): the run's skin (``axdf run --skin``, a job's
``skin:``; :mod:`axdf_cli.specs.skin`) worn over the muscles and bones, frame by frame.

Before the first frame, the skin's rest mesh is checked against the run's muscles and worn
bones by winding number (:func:`worn_rest`): what lies outside it (a skin worn over muscles it
was not fitted to, or a fit that left a few vertices out) is grown over once, as ``axdf skin
--push`` grows a fitted body (:func:`~axdf_cli.geometry.grow.grow_over`), so every point starts
inside; more than ``tol.SKIN_FOREIGN_MUSCLE_SHARE`` of the muscle vertices (or
``tol.SKIN_FOREIGN_BONE_SHARE`` of the bone points) outside is a run warning naming the
command that refits the skin (:meth:`SkinStage.warnings`). Each frame, in order:

1. **skinning**: the skin's rest mesh by its bones' world transforms relative to rest, by the
   skin file's ``skinning:`` (default :data:`DEFAULT_SKINNING`, delta mush;
   :mod:`axdf_cli.model.skinning`) (the bones :func:`~axdf_cli.model.skeleton.forward_kinematics` gives the chunk);
   with the skin's ``jiggle:``, each vertex lags behind that as a damped spring would
   (:func:`jiggle_coefficients`);
2. **push**: every candidate point (a muscle or bone mesh vertex, or a bone triangle's
   centroid, within ``tol.SKIN_REACH`` of the rest skin, built once by
   :meth:`SkinStage.start`) is compared with each of its ``tol.SKIN_CANDIDATES`` nearest rest
   skin vertices, along that vertex's skinned normal; where it lies less deep under the skin
   than its target (its local fat thickness, or its depth at rest where that is shallower: the
   rest skin is worn as fitted), the vertex is pushed outward by the difference, in full
   within ``tol.SKIN_SPREAD_IN`` times the vertex's longest edge across its normal, fading
   smoothly to nothing at ``tol.SKIN_SPREAD_OUT`` times it. A point more than
   ``tol.SKIN_MAX_HEIGHT`` above a vertex pushes nothing (a crease: the adductors between the
   thighs, where the vertex may be on the other leg), and from ``tol.SKIN_SOFT_HEIGHT`` up its
   push fades to that (:func:`~axdf_cli.model.skin.push_floor`: every push is a continuous
   function of the positions, so the skin does not pop);
3. **relax**: ``tol.SKIN_RELAX_ITERATIONS`` passes of uniform Laplacian smoothing of the
   offsets, each held at least at its push (sticky), so that the pushes become
   smooth bulges and the rest of the skin slides with them;
4. **volume**: the excess over the rest volume taken back from the vertices with room under
   them (:func:`keep_volume`).

The stage makes one part (:meth:`SkinStage.parts`: ``skin``, of kind skin) and one table
(``skin.csv``); the sinks write them as every part and table. The kernels are
:mod:`axdf_cli.model.skin`'s. Each frame is computed alone (a loop over the
chunk's frames; the kernels loop over vertices in a fixed order), so a frame's skin is the same bytes whichever frames
share its chunk: ``--jobs``, ``--resume`` and ``--frames`` subsets agree. The stage leaves
the skin's frames in ``chunk.parts["skin"]`` and its measures in ``chunk.tables["skin.csv"]``
for the sinks; it changes no muscle.
"""
from __future__ import annotations

import os

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from scipy.spatial import cKDTree

from axdf_cli import tolerances as tol
from axdf_cli.geometry.grow import grow_over
from axdf_cli.geometry.winding import inside
from axdf_cli.model import skin as kernels
from axdf_cli.model.skeleton import bones_below, forward_kinematics
from axdf_cli.model.skinning import mush_rest, skin_points
from axdf_cli.parts import COLORS, Kind, Part, PartFrames, Table
from axdf_cli.pipeline.stage import RunInputs, Scope, StageBase

#: The skin's name among a run's meshes (``meshes/skin/``); no muscle may have it.
SKIN_NAME = "skin"
#: skin.csv's numeric columns: the skin's volume (m^3) and its ratio to the skin's as the stage
#: wears it at the rest pose (the rest mesh pushed over the bones' vertices outside it); the
#: share of every muscle vertex that lies outside the skin (measured along the skinned normal of
#: its nearest candidate skin vertex, after the push); the largest outward push (m); the share
#: of the worn bones' points (their meshes' vertices and triangle centroids) outside the skin,
#: by the same test.
SKIN_COLUMNS = ("volume", "volume_ratio", "outside", "push", "bone_outside")
#: The skinning method of a skin file that names none (docs/SKIN.md: measured against the
#: others by make bench, it folds the fewest vertices over the walks' and the hop's flexion).
DEFAULT_SKINNING = "delta_mush"
#: The run's table of the skin's measures: a row per frame.
SKIN_CSV = "skin.csv"


#: The skin's table: a row per frame (:data:`SKIN_COLUMNS`).
SKIN_TABLE = Table(SKIN_CSV, SKIN_COLUMNS)


@dataclass
class SkinModel:
    """What the stage computes once (:meth:`SkinStage.start`): the skin's rest mesh and
    weights, its 1-ring, and the candidate points with their skin vertices and targets."""

    rest: np.ndarray  # (V, 3) rest vertices
    faces: np.ndarray  # (F, 3)
    weights: np.ndarray  # (V, K) dense
    bones: np.ndarray  # (K,) skeleton bone index of each weight column
    inv_rest: np.ndarray  # (K, 4, 4) the bones' rest world transforms, inverted
    ring_ptr: np.ndarray  # CSR of the 1-ring: neighbours of vertex v are ring_idx[ring_ptr[v]:ring_ptr[v+1]]
    ring_idx: np.ndarray
    muscle_points: np.ndarray  # (Nm,) candidate muscle vertices, indices into the muscles' vertices concatenated
    bone_points: list  # [(bone index, (Nb, 3) local vertices)] candidate bone vertices
    candidates: np.ndarray  # (Nm + sum Nb, k) each candidate's nearest rest skin vertices
    pairs: np.ndarray  # (Nm + sum Nb, k) those it lies under at rest, the others -1
    target: np.ndarray  # (Nm + sum Nb, k) required depth under each (m; < 0: above it, as at rest)
    spread: np.ndarray  # (2, V) how far across its normal a point pushes each vertex in full, and at all (m)
    n_muscle_vertices: int
    rest_volume: float
    room: np.ndarray  # (V,) how far each skin vertex may come in from where it is skinned (m)
    jiggle: tuple | None = None  # (coefficients (J,), their step in frames, each vertex's gain (V,), the pose)
    n_bone_points: int = 0  # every point of the worn bones (vertices and triangle centroids), candidates or not
    skinning: str = DEFAULT_SKINNING  # the method (axdf_cli.model.skinning.SKINNING)
    mush: tuple | None = None  # delta_mush: (faces, ring_ptr, ring_idx, iterations, step, rest deltas (V, 3))


def ring(faces: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
    """The mesh's 1-ring as CSR (indptr, indices), neighbours sorted."""
    i = np.concatenate([faces[:, 0], faces[:, 1], faces[:, 2], faces[:, 1], faces[:, 2], faces[:, 0]])
    j = np.concatenate([faces[:, 1], faces[:, 2], faces[:, 0], faces[:, 0], faces[:, 1], faces[:, 2]])
    adj = sp.csr_matrix((np.ones(len(i)), (i, j)), shape=(n, n))
    adj.sum_duplicates()
    adj.sort_indices()
    return adj.indptr.astype(np.int64), adj.indices.astype(np.int64)


@dataclass(frozen=True)
class WornRest:
    """The skin's rest mesh as the run wears it (:func:`worn_rest`)."""

    vertices: np.ndarray  # (V, 3) the skin file's rest mesh, grown over what lay outside it
    muscle_outside: float  # the share of the muscles' rest vertices outside the file's mesh (winding number)
    bone_outside: float  # the share of the worn bones' points (vertices, triangle centroids) outside it
    grown: int  # how many points were grown over


def _bone_points(skin, plan) -> list:
    """[(bone index, (N, 3) bone-local points)]: each worn bone's mesh vertices and triangle
    centroids (a coarse mesh's faces bulge between its vertices). The worn bones are those the
    skin is bound to and every bone below them (:func:`~axdf_cli.model.skeleton.bones_below`:
    a patella, a talus); a root above them (gait2392's ground) is left out."""
    skel = plan.pose.skeleton
    weighed = bones_below(skel, {skel.bone_index[b] for b in skin.bones})
    out = []
    for b, (bv, bf, _) in sorted(plan.contact_meshes.items()):
        if b in weighed:
            bv = np.asarray(bv, dtype=np.float64)
            out.append((int(b), np.concatenate([bv, bv[np.asarray(bf, np.int64)].mean(axis=1)])))
    return out


def worn_rest(skin, plan) -> WornRest:
    """The skin's rest mesh with every muscle vertex and worn bone point of the run at rest
    inside it: the points outside it by winding number are grown over
    (:func:`~axdf_cli.geometry.grow.grow_over`), the rest of the mesh as the file has it."""
    skel = plan.pose.skeleton
    rest_world = forward_kinematics(skel, skel.rest_coordinates()[None])[0]
    muscle = np.concatenate([np.zeros((0, 3))] + [m.rest_vertices.astype(np.float64) for m in plan.models])
    bone = np.concatenate([np.zeros((0, 3))] + [local @ rest_world[b, :3, :3].T + rest_world[b, :3, 3]
                                                for b, local in _bone_points(skin, plan)])
    v = np.ascontiguousarray(skin.vertices, dtype=np.float64)
    faces = np.ascontiguousarray(skin.faces, dtype=np.int64)
    pts = np.concatenate([muscle, bone])
    out = ~inside(v, faces, pts) if len(pts) else np.zeros(0, bool)
    share = (float(out[:len(muscle)].mean()) if len(muscle) else 0.0,
             float(out[len(muscle):].mean()) if len(bone) else 0.0)
    if out.any():
        v = grow_over(v, faces, pts[out])
    return WornRest(v, share[0], share[1], int(out.sum()))


def build(skin, plan, worn: WornRest | None = None, skinning: str | None = None) -> SkinModel:
    """The stage's model: the skin's 1-ring, and the candidate points (muscle and bone
    vertices near the rest skin as worn, :func:`worn_rest`) with their nearest rest skin
    vertices and target depths; ``skinning`` (else the skin file's, else
    :data:`DEFAULT_SKINNING`) the method, with its delta mush deltas when it is ``delta_mush``."""
    skel = plan.pose.skeleton
    rest_world = forward_kinematics(skel, skel.rest_coordinates()[None])[0]
    bones = np.array([skel.bone_index[b] for b in skin.bones], dtype=np.int64)
    faces = np.ascontiguousarray(skin.faces, dtype=np.int64)
    v = np.ascontiguousarray((worn or worn_rest(skin, plan)).vertices, dtype=np.float64)
    ptr, idx = ring(faces, len(v))
    normals = np.empty_like(v)
    kernels.normals_volume(v, faces, normals)
    tree = cKDTree(v)
    k = min(tol.SKIN_CANDIDATES, len(v))

    muscle = np.concatenate([m.rest_vertices.astype(np.float64) for m in plan.models]) if plan.models \
        else np.zeros((0, 3))
    reach = tol.SKIN_REACH + float(skin.fat.max(initial=0.0))
    near = np.isfinite(tree.query(muscle, k=1, distance_upper_bound=reach)[0]) if len(muscle) else \
        np.zeros(0, bool)
    muscle_points = np.flatnonzero(near)
    pts = [muscle[muscle_points]]
    bone_points = []
    n_bone = 0
    for b, local in _bone_points(skin, plan):
        world = local @ rest_world[b, :3, :3].T + rest_world[b, :3, 3]
        n_bone += len(local)
        keep = np.isfinite(tree.query(world, k=1, distance_upper_bound=reach)[0])
        if keep.any():
            bone_points.append((int(b), local[keep]))
            pts.append(world[keep])
    p = np.ascontiguousarray(np.concatenate(pts))
    cand = np.asarray(tree.query(p, k=k, workers=-1)[1], dtype=np.int64).reshape(len(p), k) if len(p) else np.zeros((0, k), np.int64)
    nearest, height = np.empty(len(p), np.int64), np.empty(len(p))
    kernels.nearest_heights(p, v, normals, cand, nearest, height)
    # the fat, or the rest depth where shallower: the rest skin is worn as fitted (axdf skin --push
    # clears the muscles and the bones by the winding number; a point the normal test reads above
    # a concave patch, the face over a skull, stays where it was)
    # Each point is held under each of its candidate vertices it lies under at rest (its nearest,
    # and those whose normal puts it below them: not the other thigh's skin across the crease).
    h_rest = np.einsum("pkc,pkc->pk", p[:, None, :] - v[cand], normals[cand])
    target = np.minimum(skin.fat[nearest][:, None], -h_rest)
    pairs = np.where((h_rest <= 0.0) | (cand == nearest[:, None]), cand, -1)
    edge = np.linalg.norm(v[np.repeat(np.arange(len(v)), np.diff(ptr))] - v[idx], axis=1)
    longest = np.maximum.reduceat(edge, ptr[:-1]) if len(idx) else np.zeros(len(v))  # (every vertex has a ring)
    spread = np.stack([tol.SKIN_SPREAD_IN * longest, tol.SKIN_SPREAD_OUT * longest])
    # room: at rest, the distance from each skin vertex to the nearest candidate point, less its
    # fat (a vertex with no point within reach: the volume step's cap)
    dist = cKDTree(p).query(v, k=1, distance_upper_bound=reach)[0] if len(p) else np.full(len(v), np.inf)
    room = np.minimum(np.maximum(dist - skin.fat, 0.0), tol.SKIN_VOLUME_MAX_SHIFT)
    model = SkinModel(v, faces, np.ascontiguousarray(skin.weights, dtype=np.float64), bones,
                      np.linalg.inv(rest_world[bones]), ptr, idx, muscle_points, bone_points, cand, pairs,
                      np.ascontiguousarray(target), np.ascontiguousarray(spread), int(len(muscle)), 1.0, room,
                      n_bone_points=n_bone, skinning=skinning or skin.skinning or DEFAULT_SKINNING)
    if model.skinning == "delta_mush":
        model.mush = (faces, ptr, idx, tol.SKIN_MUSH_ITERATIONS, tol.SKIN_MUSH_STEP,
                      mush_rest(v, faces, ptr, idx, tol.SKIN_MUSH_ITERATIONS, tol.SKIN_MUSH_STEP))
    model.rest_volume = float(skin_frame(model, rest_world, p, keep=False)[2][0])  # the skin as worn at rest
    return model


def jiggle_span(jiggle, fps: float) -> tuple[float, float]:
    """How far back the skin's jiggle remembers the bones (seconds: until the spring's response
    has decayed to a thousandth, at most ``tol.SKIN_JIGGLE_MEMORY``) and the step (in frames)
    it samples that span at: every frame while that is at most ``tol.SKIN_JIGGLE_TAPS``
    samples, else ``tol.SKIN_JIGGLE_TAPS`` samples evenly over it (the pose sampled between its
    frames), so that the filter's work and memory follow the output, not the pose's fps."""
    w = 2.0 * np.pi * jiggle.frequency
    span = min(np.log(1000.0) / (jiggle.damping_ratio * w), tol.SKIN_JIGGLE_MEMORY)
    n = int(np.ceil(span * fps)) + 1
    return span, (1.0 if n <= tol.SKIN_JIGGLE_TAPS else span * fps / (tol.SKIN_JIGGLE_TAPS - 1))


def jiggle_coefficients(jiggle, fps: float) -> np.ndarray:
    """The skin's jiggle as a filter over the bones' past: a vertex on a damped spring (natural
    frequency ``f``, damping ratio ``z``) behind where skinning puts it, ``x``, lags by ``e`` with
    ``e'' + 2 z w e' + w^2 e = -x''``: the convolution of ``-x''`` with the spring's impulse
    response ``exp(-z w t) sin(w_d t) / w_d``. ``x`` is linear in the bones' transforms ``M``
    (each relative to rest), and so is ``e``: ``e(f) = blend(sum_j c[j] M(f - j h))`` with
    ``c`` the response sampled every ``h`` frames (:func:`jiggle_span`: 1, or more for a pose of
    very many frames per second) and convolved with the central second difference
    ``[1, -2, 1] / dt^2``, ``dt = h / fps``. The response is cut after it has decayed to a
    thousandth, or after ``tol.SKIN_JIGGLE_MEMORY`` seconds. Every frame is computed from the
    pose alone (frames before the pose's first hold its first): the same bytes whichever frames
    a process computes. Sum of ``c``: 0, so a skeleton at rest never jiggles."""
    w = 2.0 * np.pi * jiggle.frequency
    z = jiggle.damping_ratio
    wd = w * np.sqrt(1.0 - z * z)
    span, step = jiggle_span(jiggle, fps)
    dt = step / fps
    n = int(np.ceil(span / dt)) + 1
    t = np.arange(n) * dt
    response = np.exp(-z * w * t) * np.sin(wd * t) / wd * dt  # (the integral's dt)
    # x'' at frame f - k h by the central difference: the response is 0 at k = 0, so x(f + h)'s
    # coefficient is 0 and the filter needs no frame after f
    return (-np.convolve(response, [1.0, -2.0, 1.0]) / (dt * dt))[1:]


def jiggle_lag(model: SkinModel, frames: np.ndarray) -> np.ndarray:
    """Each skin vertex's lag at ``frames`` (C, V, 3): :func:`jiggle_coefficients` applied to
    the bones' transforms at the samples before each (the pose sampled there), a frame at a
    time (at most ``tol.SKIN_JIGGLE_TAPS + 1`` skeletons in memory)."""
    from axdf_cli.model.pose import sample_coordinates

    coef, step, gain, pose = model.jiggle
    out = np.empty((len(frames), len(model.rest), 3))
    back = np.arange(len(coef)) * step  # (J,) frames back
    for i, f in enumerate(np.asarray(frames, np.float64)):
        world = forward_kinematics(pose.skeleton, sample_coordinates(pose, f - back))[:, model.bones]
        rel = (world @ model.inv_rest)[:, :, :3, :]  # (J, K, 3, 4)
        # mix[k,a,b] = sum_j coef[j] rel[j,k,a,b]
        mix = np.ascontiguousarray(np.einsum("j,jkab->kab", coef, rel))
        kernels.blend(model.weights, mix, model.rest, out[i])
    return out * gain[:, None]


def vertex_areas(x: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Each vertex's share of the mesh's area: a third of its triangles' (m^2)."""
    a = 0.5 * np.linalg.norm(np.cross(x[faces[:, 1]] - x[faces[:, 0]], x[faces[:, 2]] - x[faces[:, 0]]), axis=1)
    return np.bincount(faces.ravel(), weights=np.repeat(a / 3.0, 3), minlength=len(x))


def uniform_depth(area: np.ndarray, slack: np.ndarray, volume: float) -> float:
    """The depth ``d`` such that moving every vertex in by ``min(d, slack)`` takes ``volume``
    (to first order: sum of area * min(d, slack)); the largest slack where even that is short."""
    order = np.argsort(slack, kind="stable")
    s, a = slack[order], area[order]
    below = np.concatenate([[0.0], np.cumsum(a * s)])  # taken by the vertices whose slack is under s_k
    rest = area.sum() - np.concatenate([[0.0], np.cumsum(a)])  # the area still taking d
    taken = below[:-1] + s * rest[:-1]  # at d = s_k
    k = int(np.searchsorted(taken, volume))
    if k >= len(s):
        return float(s[-1]) if len(s) else 0.0
    return float((volume - below[k]) / rest[k]) if rest[k] > 0 else float(s[k])


def keep_volume(model: SkinModel, x: np.ndarray, n: np.ndarray, offset: np.ndarray, floor: np.ndarray) -> None:
    """Hold the skin's volume at its rest volume (in place on ``offset``). The pushes and the
    relax only add volume (a bulge over a bending muscle, a crease filled); what is over is
    taken back from the vertices with room under them: each comes in by a common depth, at most
    its slack above ``floor`` (the points under it stay at their fat depth; a vertex with
    none under it, its ``room`` under where it is skinned) and at most
    ``tol.SKIN_VOLUME_MAX_SHIFT``, its edges tapered by ``tol.SKIN_VOLUME_TAPER`` passes. A
    skin short of its volume (a collapse at a bending joint) comes out evenly, by at most the
    same depth. ``tol.SKIN_VOLUME_ROUNDS`` rounds, each on the moved mesh."""
    area = vertex_areas(x, model.faces)
    cap = tol.SKIN_VOLUME_MAX_SHIFT
    slack = np.maximum(np.minimum(offset - floor, cap), 0.0)
    out = 0.0
    scratch = np.empty_like(x)
    for _ in range(tol.SKIN_VOLUME_ROUNDS):
        excess = kernels.normals_volume(x + n * offset[:, None], model.faces, scratch) - model.rest_volume
        if excess > 0.0:
            shift = np.minimum(uniform_depth(area, slack, excess), slack)
            kernels.taper(shift, slack, model.ring_ptr, model.ring_idx, tol.SKIN_VOLUME_TAPER)
            offset -= shift
            slack -= shift
        else:
            d = min(-excess / area.sum(), cap - out)
            offset += d
            out += d


def skinned(model: SkinModel, world: np.ndarray) -> np.ndarray:
    """(V, 3) float64: the rest skin skinned by ``world`` (B, 4, 4), the skeleton's bones' world
    transforms, by the model's method (:func:`~axdf_cli.model.skinning.skin_points`), before
    any jiggle or push."""
    rel = np.ascontiguousarray((world[model.bones] @ model.inv_rest)[:, :3, :])  # (K, 3, 4)
    x = np.empty((len(model.rest), 3))
    skin_points(model.skinning, model.weights, rel, model.rest, x, model.mush)
    return x


def skin_frame(model: SkinModel, world: np.ndarray, points: np.ndarray, keep: bool = True, lag=None) -> tuple:
    """One frame: the skin skinned by ``world`` (B, 4, 4) (and moved by its jiggle's ``lag``,
    (V, 3)), pushed over ``points`` (the
    candidates' world positions, (N, 3)), relaxed and (``keep``) held at its rest volume →
    (positions (V, 3), normals (V, 3), measures (len(SKIN_COLUMNS),) with the outside shares
    still to divide)."""
    nv = len(model.rest)
    x, n = skinned(model, world), np.empty((nv, 3))
    if lag is not None:
        x += lag
    kernels.normals_volume(x, model.faces, n)
    floor, offset = np.empty(nv), np.empty(nv)
    kernels.push_floor(points, x, n, model.pairs, model.target, model.spread[0], model.spread[1], model.room,
                       tol.SKIN_SOFT_HEIGHT, tol.SKIN_MAX_HEIGHT, floor)
    need = np.where(floor > 0.0, floor, np.nan)  # pushed out; the rest free (NaN) for the relax
    kernels.relax(need, model.ring_ptr, model.ring_idx, tol.SKIN_RELAX_ITERATIONS, offset)
    if keep:
        keep_volume(model, x, n, offset, floor)
    y = x + n * offset[:, None]
    ny = np.empty_like(y)
    vol = kernels.normals_volume(y, model.faces, ny)
    nm, npts = len(model.muscle_points), len(points)
    nearest, height = np.empty(npts, np.int64), np.empty(npts)
    kernels.nearest_heights(points, x, n, model.candidates, nearest, height)
    at = np.argmax(model.candidates == nearest[:, None], axis=1)  # (the nearest is a candidate)
    allowed = np.maximum(-model.target[np.arange(npts), at], 0.0)
    outside = kernels.count_outside(points[:nm], y, n, nearest[:nm], allowed[:nm])
    bone_outside = kernels.count_outside(points[nm:], y, n, nearest[nm:], allowed[nm:])
    return y, ny, np.array([vol, vol / model.rest_volume, float(outside), float(offset.max(initial=0.0)),
                            float(bone_outside)])


class SkinStage(StageBase):
    """The skin stage (module doc): in the run when it has a skin (``for_run``; it is not
    switched by name)."""

    name = "skin"
    scope = Scope.FRAME
    tables = (SKIN_TABLE,)

    @classmethod
    def for_run(cls, inputs: RunInputs) -> "SkinStage | None":
        """The stage for a run that wears a skin; ``--no-jiggle`` (a job's ``jiggle: false``)
        stills the skin's jiggle as well as the muscles'."""
        if inputs.skin is None:
            return None
        return cls(inputs.skin, jiggle=inputs.switches.get("jiggle", True))

    def worn(self, plan) -> WornRest:
        """The rest skin as this run wears it (:func:`worn_rest`; computed once per stage)."""
        if self._worn is None:
            self._worn = worn_rest(self.skin, plan)
        return self._worn

    def warnings(self, plan) -> list[str]:
        """A skin worn over muscles it was not fitted to: how much lay outside it, and the
        command that fits it over them."""
        w = self.worn(plan)
        if w.muscle_outside <= tol.SKIN_FOREIGN_MUSCLE_SHARE and w.bone_outside <= tol.SKIN_FOREIGN_BONE_SHARE:
            return []
        dirs = sorted({os.path.dirname(str(m.source)) for m in plan.muscles if getattr(m, "source", None)})
        folder = os.path.commonpath(dirs) if dirs else "MUSCLES_DIR"
        return [f"skin {self.skin.name}: {100 * w.muscle_outside:.1f}% of the muscle vertices and "
                f"{100 * w.bone_outside:.2f}% of the worn bones' points lie outside it at rest (it was fitted over "
                f"other muscles, or none): the run grows it over them before the first frame; to fit it over these: "
                f"axdf skin --skeleton {plan.pose.skeleton_path} --muscles {folder} --push --out DIR"]

    def parts(self, plan) -> tuple:
        """The skin: one part, of kind skin (its rest mesh as worn), its rest normals those of
        the kernels."""
        v = np.ascontiguousarray(self.worn(plan).vertices, np.float64)
        normals = np.zeros_like(v)
        kernels.normals_volume(v, np.ascontiguousarray(self.skin.faces, np.int64), normals)
        return (Part(SKIN_NAME, Kind.SKIN, self.skin.faces, v, normals, COLORS[Kind.SKIN]),)

    def __init__(self, skin, jiggle: bool = True):
        self.skin = skin
        self.jiggle = jiggle  # False: the run's --no-jiggle (a job's jiggle: false) stills the skin too
        self._worn: WornRest | None = None
        self.skinning = skin.skinning or DEFAULT_SKINNING

    @property
    def settings(self) -> dict:
        out = {"skin": self.skin.name, "skeleton": self.skin.skeleton, "vertices": int(len(self.skin.vertices)),
               "reach": tol.SKIN_REACH, "candidates": tol.SKIN_CANDIDATES,
               "soft_height": tol.SKIN_SOFT_HEIGHT, "max_height": tol.SKIN_MAX_HEIGHT,
               "spread": [tol.SKIN_SPREAD_IN, tol.SKIN_SPREAD_OUT], "jiggle_memory": tol.SKIN_JIGGLE_MEMORY,
               "relax": tol.SKIN_RELAX_ITERATIONS,
               "volume": {"max_shift": tol.SKIN_VOLUME_MAX_SHIFT, "taper": tol.SKIN_VOLUME_TAPER,
                          "rounds": tol.SKIN_VOLUME_ROUNDS},
               "skinning": self.skinning}
        if self.skinning == "delta_mush":
            out["mush"] = {"iterations": tol.SKIN_MUSH_ITERATIONS, "step": tol.SKIN_MUSH_STEP}
        j = self.skin.jiggle
        if j is not None:  # (a skin without one keeps its runs' settings as they were)
            out["jiggle"] = {"frequency": j.frequency, "damping_ratio": j.damping_ratio, "amount": j.amount,
                             "taps": tol.SKIN_JIGGLE_TAPS} if self.jiggle else False
        return out

    def start(self, plan) -> SkinModel:
        model = build(self.skin, plan, self.worn(plan))
        j = self.skin.jiggle if self.jiggle else None
        if j is not None:
            gain = j.amount * self.skin.fat / max(float(self.skin.fat.max(initial=0.0)), 1e-12)
            model.jiggle = (jiggle_coefficients(j, plan.pose.fps), jiggle_span(j, plan.pose.fps)[1], gain,
                            plan.pose)
        return model

    def __call__(self, state: SkinModel, chunk):
        nf = len(chunk.frames)
        nv = len(state.rest)
        pos = np.empty((nf, nv, 3), np.float32)
        nrm = np.empty((nf, nv, 3), np.float32)
        stats = np.zeros((nf, len(SKIN_COLUMNS)))
        js = sorted(chunk.results)
        lag = jiggle_lag(state, chunk.frames) if state.jiggle is not None else [None] * nf
        for i in range(nf):
            everything = np.concatenate([chunk.results[j].vertices[i] for j in js]) if js else np.zeros((0, 3))
            pts = [everything[state.muscle_points]]
            for b, local in state.bone_points:
                w = chunk.world[i, b]
                pts.append(local @ w[:3, :3].T + w[:3, 3])
            y, ny, st = skin_frame(state, chunk.world[i], np.ascontiguousarray(np.concatenate(pts)), lag=lag[i])
            pos[i], nrm[i] = y, ny
            st[2] /= max(state.n_muscle_vertices, 1)
            st[4] /= max(state.n_bone_points, 1)
            stats[i] = st
        chunk.parts[SKIN_NAME] = PartFrames(pos, nrm)
        chunk.tables[SKIN_CSV] = stats
        return state, chunk
