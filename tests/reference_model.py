"""The numpy formulation of step 1b (:meth:`MuscleModel.surface`): the reference the compiled
batch pass (:mod:`axdf_cli.model.batch`) is tested against
(``tests/test_batch.py``). Written with whole-array numpy operations over frames: the RMF by
:func:`axdf_cli.model.rmf.propagate`, the bound points' frames by one
:func:`~axdf_cli.model.rmf.reflect_step`, the twist, the tension law and the split into the
fixed and the volume-scaled parts of the bound control points; the surface itself by
:func:`surface_kernel.surface_stage` (tested against ``reference_surface.py``)."""
from __future__ import annotations

import numpy as np

from axdf_cli import tolerances as tol
from axdf_cli.model import rmf
from axdf_cli.model.muscle import FrameResult, VolumeMode
import surface_kernel

#: Modes whose scale is solved against the rest volume (the others keep their start scale).
SOLVED_MODES = frozenset({VolumeMode.EXACT})


def start_scale(mode: VolumeMode, ratio: np.ndarray) -> np.ndarray:
    """The scale a frame starts from, l0 / l1 = ``ratio`` (F,): 1 for ``none``, the paper's
    sqrt(l0/l1) otherwise (``exact`` solves from there)."""
    if mode is VolumeMode.NONE:
        return np.ones_like(ratio)
    return np.sqrt(ratio)


def _unit(d: np.ndarray) -> np.ndarray:
    return d / np.maximum(np.linalg.norm(d, axis=-1, keepdims=True), 1e-300)


def _apply(model, b: str, p: np.ndarray) -> np.ndarray:
    """X[f,s,c] = sum_i B[s,i] P[f,i,c] for the basis matrix named ``b`` (its sparse rows)."""
    idx, w = model.sparse[b]
    return np.einsum("sk,fskc->fsc", w, p[:, idx])


def axis_frames(model, world: np.ndarray, p: np.ndarray, coarse: bool = False):
    """Samples x, unit tangents t and RMF reference vectors r (F, S, 3) of axis points p (F, n, 3)."""
    b, db = ("Bc", "dBc") if coarse else ("Bs", "dBs")
    x, t = _apply(model, b, p), _unit(_apply(model, db, p))
    r0 = rmf.perpendicular_unit(world[:, model.origin_bone, :3, :3] @ model.r0_local, t[:, 0])
    return x, t, rmf.propagate(x, t, r0)


def roll(model, world, t_end, r_end):
    """Insertion roll (radians, wrapped) from the propagated r_end at t = 1: (F,)."""
    target = rmf.perpendicular_unit(world[:, model.insertion_bone, :3, :3] @ model.rend_local, t_end)
    return rmf.signed_angle(r_end, target, t_end)


def length(model, p: np.ndarray, blas: bool = True) -> np.ndarray:
    """Arc length (F,): |C'| at the Gauss-Legendre points against their weights, summed by
    ``@`` (OpenBLAS's dot, whose order changes with the number of frames: one frame's length
    can differ in the last bit with the chunk it is in) or, with ``blas=False``, in order."""
    speed = np.linalg.norm(_apply(model, "dBg", p), axis=-1)  # (F, G)
    if blas:
        return speed @ model.gw
    out = np.zeros(len(p))
    for g in range(speed.shape[1]):
        out = out + speed[:, g] * model.gw[g]
    return out


def reference_step_1b(model, world: np.ndarray, points: np.ndarray, tension: np.ndarray,
                      twist_reference: np.ndarray | None = None, rest_volume="model", blas: bool = True
                      ) -> FrameResult:
    """Step 1b of ``model`` in numpy: world (F, B, 4, 4), points (F, n, 3), tension (F,),
    twist_reference (F,) or None; as :meth:`MuscleModel.surface` was (its warnings left out);
    ``blas``: the arc length's sum by ``@`` (OpenBLAS's order) or in order (:func:`length`)."""
    p = points
    x, t, r = axis_frames(model, world, p)
    theta = roll(model, world, t[:, -1], r[:, -1])
    if twist_reference is None:
        theta = np.unwrap(theta)
    else:
        theta = theta + 2.0 * np.pi * np.round((twist_reference - theta) / (2.0 * np.pi))
    c = _apply(model, "Bb", p)
    tt = _unit(_apply(model, "dBb", p))
    j = model.bind_j
    rr = rmf.reflect_step(x[:, j], t[:, j], r[:, j], c, tt)
    ss = np.cross(tt, rr)
    ang = theta[:, None] * model.lam[None, :]
    ca, sa = np.cos(ang)[..., None], np.sin(ang)[..., None]
    rr, ss = ca * rr + sa * ss, ca * ss - sa * rr
    u, v, w = model.uvw[:, 0, None], model.uvw[:, 1, None], model.uvw[:, 2, None]
    off = u * tt + v * rr + w * ss
    ln = length(model, p, blas)
    e = np.clip(np.asarray(tension, dtype=np.float64), 0.0, 1.0)
    ratio = model.l0 / np.maximum(ln, tol.MIN_AXIS_LENGTH)
    s = start_scale(model.volume_mode, ratio)
    tau = np.sqrt(1.0 + tol.TENSION_GAIN * e[:, None] * (2.0 * model.bump[None, :] - 1.0) * model.beta[None, :])
    h = e[:, None] * model.bump[None, :]
    beta = model.beta[None, :, None]
    held = (beta * (tau * h * s[:, None])[..., None]) * off
    fixed = c + (1.0 - beta) * off + held
    scaled = beta * (tau * (1.0 - h))[..., None] * off
    if isinstance(rest_volume, str):
        rest_volume = model.v0
    v0 = rest_volume if model.volume_mode in SOLVED_MODES else None
    nf = len(p)
    verts = np.empty((nf, model.n_vertices, 3))
    norms = np.empty((nf, model.n_vertices, 3))
    volume, scale, bad = np.empty(nf), np.empty(nf), np.zeros(nf, dtype=np.bool_)
    surface_kernel.surface_stage(np.ascontiguousarray(fixed), np.ascontiguousarray(scaled), np.ascontiguousarray(p[:, 0]),
                                 np.ascontiguousarray(p[:, -1]), np.ascontiguousarray(-t[:, 0]),
                                 np.ascontiguousarray(t[:, -1]), model.u_idx, model.u_w, model.v_idx, model.v_w,
                                 v0 is not None, float(v0 or 0.0), np.ascontiguousarray(s, dtype=np.float64),
                                 tol.SCALE_MIN, tol.SCALE_MAX, tol.VOLUME_SOLVE_ITERS, tol.VOLUME_SOLVE_RTOL, verts,
                                 norms, volume, scale, bad)
    return FrameResult(verts, norms, ln, volume, np.clip(scale, tol.SCALE_MIN, tol.SCALE_MAX), np.degrees(theta), e,
                       [(int(i), "no solution") for i in np.nonzero(bad)[0]])
