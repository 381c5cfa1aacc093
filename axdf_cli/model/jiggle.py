"""Secondary motion ("jiggle"): the free axis control points ring after the bones stop.

The law. Every axis control point p of a muscle with ``jiggle`` follows its kinematic target
T(t) (where the bones put it) as an independent, critically or under- or over-damped
oscillator of natural frequency f (omega = 2 pi f) and damping ratio zeta:

    x'' = omega^2 (T - x) - 2 zeta omega (x' - T')

so the offset e = x - T obeys ``e'' + 2 zeta omega e' + omega^2 e = -T''``. Between two
frames the target moves linearly in time (T'' = 0, T' the frame difference over dt), so
inside a step e is the free motion of a linear oscillator and one step of length h is exact:

    [e, e'](t + h) = Phi(h) [e, e'](t),    Phi(h) = exp(A h),    A = [[0, 1], [-omega^2, -2 zeta omega]]

With a = zeta omega and d^2 = omega^2 (zeta^2 - 1), A = -a I + N with N^2 = d^2 I, so

    Phi = e^{-a h} [[c + a s, s], [-omega^2 s, c - a s]],   c = cosh(d h),  s = sinh(d h) / d

(cos(mu h) and sin(mu h) / mu, mu^2 = -d^2, when under-damped; 1 and h when critical; for a
strongly over-damped step, the same matrix from its two real roots, which never overflows).
The response to a step of the bone is the textbook one: it rings at f sqrt(1 - zeta^2) and
successive extrema fall by exp(-pi zeta / sqrt(1 - zeta^2)). The integration is exact for
any frame rate (no substeps, unconditionally stable), so a pose keyed at 30, 60 or 120 fps
moves the same way up to how finely its target is sampled. A step's energy
``E = (|e'|^2 + omega^2 |e|^2) / 2`` never grows (it decays when zeta > 0); only the bones'
changes of velocity between frames put energy in.

Before the first frame of the pose the muscle has moved for ever at the velocity of the
pose's first step (a pre-roll at constant velocity), so a motion already under way at its
first frame has no start-up transient. Under a target moving at constant velocity V
(T'' = 0) every free solution decays, and what is left is the steady state e = 0, e' = 0:
since the damping acts on the velocity relative to the target, the oscillator rides exactly
on the target, x = T, x' = V (:func:`steady_state`; the same state the integrator reaches
on a long constant-velocity pre-roll, as ``exp(-zeta omega t)``). A pose that starts still
starts at rest on its target.

Where the muscle is held. What is written is ``T + w (x - T)``: a weight w per control
point, 0 at the origin and insertion (held by their bones), from the muscle's ``weight``
profile along the axis (default sin(pi u)), taken at each control point's Greville abscissa
u (the parameter a quadratic B-spline's control point mainly acts at).

The bound. A motion too fast for its frame rate (or wrongly timed) would throw the free points
far off: the offset grows as the target's acceleration over omega^2. What is written is
bounded instead, relative to the muscle's size: each control point's offset d = w (x - T)
keeps its direction and its length r becomes f(r), with B = ``JIGGLE_BOUND`` times the
axis' length at that frame (its control polygon's) and K = ``JIGGLE_BOUND_KNEE`` B:

    f(r) = r                                   for r <= K
    f(r) = K + (B - K) tanh((r - K) / (B - K)) above,

which has the same value, slope and curvature at K (a soft clamp, no kink) and stays below
B (:func:`bounded`; axdf_cli/tolerances.py says why these values). The oscillators' state
is not clamped (the law stays linear and exact); only what is written is.

Tension. A tensed muscle rings faster and less (soft-tissue vibration frequency and damping
both rise with muscle force: Wakeling & Nigg, J. Appl. Physiol. 90, 2001): with effective
tension e (the tension law's), the stiffness omega^2 goes linearly from the relaxed value to
the ``tensed`` one, and so does zeta.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from axdf_cli import tolerances as tol
from axdf_cli.model import bspline


@dataclass(frozen=True)
class JiggleSpec:
    """A muscle's ``jiggle:`` (docs/FORMATS.md, "Jiggle")."""

    frequency: float  # Hz: natural frequency of the relaxed muscle
    damping_ratio: float  # zeta: 0 rings for ever, 1 is critical, above 1 over-damped
    weight: tuple[float, ...] | None = None  # profile origin → insertion (None: sin(pi u))
    tensed_frequency: float | None = None  # at full effective tension (None: as relaxed)
    tensed_damping_ratio: float | None = None


def parameters(spec: JiggleSpec, tension: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Angular frequency omega (rad/s) and damping ratio zeta at effective tensions (...,):
    the stiffness omega^2 and zeta each linear in the tension, from relaxed to ``tensed``."""
    e = np.clip(np.asarray(tension, dtype=np.float64), 0.0, 1.0)
    f1 = spec.frequency if spec.tensed_frequency is None else spec.tensed_frequency
    z1 = spec.damping_ratio if spec.tensed_damping_ratio is None else spec.tensed_damping_ratio
    omega = 2.0 * np.pi * np.sqrt((1.0 - e) * spec.frequency ** 2 + e * f1 ** 2)
    zeta = (1.0 - e) * spec.damping_ratio + e * z1
    return omega, zeta


def decay_rate(spec: JiggleSpec, samples: int = 65) -> float:
    """The slowest rate (1/s) at which a free offset dies out, over effective tensions 0..1
    (``samples`` of them): zeta omega when under- or critically damped, the slow root
    omega / (zeta + sqrt(zeta^2 - 1)) when over-damped; 0 for a muscle that rings for ever."""
    omega, zeta = parameters(spec, np.linspace(0.0, 1.0, samples))
    slow = omega / (zeta + np.sqrt(np.maximum(zeta * zeta - 1.0, 0.0)))
    return float(np.where(zeta <= 1.0, zeta * omega, slow).min())


def warmup_frames(spec: JiggleSpec, h: float, eps: float = tol.JIGGLE_WARMUP_EPS) -> float:
    """Frames of length h after which a difference of start state has fallen to ``eps`` of
    itself (``exp(-rate t) = eps``, :func:`decay_rate`): how long before a frame the
    oscillators must start for that frame not to depend on how they started. inf for an
    undamped muscle (its start is never forgotten)."""
    rate = decay_rate(spec)
    return math.inf if rate <= 0.0 else math.log(1.0 / eps) / (rate * h)


def greville(n: int) -> np.ndarray:
    """Greville abscissae (n,) of a clamped quadratic B-spline with n control points: where
    each control point mainly acts (0 for the origin, 1 for the insertion)."""
    k = bspline.clamped_knots(n, 2)
    return 0.5 * (k[1:n + 1] + k[2:n + 2])


def control_weights(weight: tuple[float, ...] | None, n: int) -> np.ndarray:
    """The weight (n,) of each of n axis control points: the profile ``weight`` (values
    evenly spaced from origin to insertion, linear between), or sin(pi u), at the Greville
    abscissae u. The origin and insertion always get 0."""
    u = greville(n)
    if weight is None:
        w = np.sin(np.pi * u)
    else:
        w = np.interp(u, np.linspace(0.0, 1.0, len(weight)), np.asarray(weight, dtype=np.float64))
    w[0] = w[-1] = 0.0
    return w


def step_matrices(omega: np.ndarray, zeta: np.ndarray, h: float) -> np.ndarray:
    """The exact step Phi(h) = exp(A h) of ``e'' + 2 zeta omega e' + omega^2 e = 0`` for every
    (omega, zeta) pair: omega, zeta (...,) → (..., 2, 2), acting on [e, e'].

    Closed form (module doc); regimes by q = (d h)^2 = (zeta^2 - 1)(omega h)^2: q < 0 rings
    (cos, sin), 0 <= q <= 1 uses cosh and sinh(x)/x (critical damping is the limit x → 0),
    q > 1 the two real roots r1 = -omega / (zeta + sqrt(zeta^2 - 1)) (slow, written without
    cancellation) and r2 = omega^2 / r1, so that no exponential overflows."""
    omega, zeta = np.broadcast_arrays(np.asarray(omega, dtype=np.float64), np.asarray(zeta, dtype=np.float64))
    a = zeta * omega
    wh = omega * h
    q = (zeta * zeta - 1.0) * wh * wh
    x = np.sqrt(np.abs(q))  # |d| h
    decay = np.exp(-a * h)
    ring = q < 0.0
    # c = cosh(dh) or cos(mu h); sx = sinh(x)/x or sin(x)/x (1 at x = 0)
    c = np.where(ring, np.cos(x), np.cosh(np.minimum(x, 1.0)))
    safe = np.where(x > 0.0, x, 1.0)
    sx = np.where(x > 0.0, np.where(ring, np.sin(x), np.sinh(np.minimum(x, 1.0))) / safe, 1.0)
    ec, es = decay * c, decay * sx * h  # e^{-ah} c, e^{-ah} s
    phi = np.empty(omega.shape + (2, 2))
    phi[..., 0, 0] = ec + a * es
    phi[..., 0, 1] = es
    phi[..., 1, 0] = -omega * omega * es
    phi[..., 1, 1] = ec - a * es
    big = q > 1.0  # strongly over-damped: from the real roots r1 (slow) and r2 (fast)
    if np.any(big):
        w, z = omega[big], zeta[big]
        root = np.sqrt(z * z - 1.0)
        r1 = -w / (z + root)
        r2 = -w * (z + root)
        e1, e2 = np.exp(r1 * h), np.exp(r2 * h)
        two_d = r1 - r2  # 2 d > 0
        phi[big, 0, 0] = (r1 * e2 - r2 * e1) / two_d
        phi[big, 0, 1] = (e1 - e2) / two_d
        phi[big, 1, 0] = -w * w * (e1 - e2) / two_d
        phi[big, 1, 1] = (r1 * e1 - r2 * e2) / two_d
    return phi


def steady_state(t0: np.ndarray, t1: np.ndarray | None, h: float) -> tuple[np.ndarray, np.ndarray]:
    """The state (x, v) at the first frame after a long pre-roll at the first step's constant
    velocity: targets t0 at that frame and t1 at the next (None: no next frame, the pose
    holds still) → x = t0, v = (t1 - t0) / h (module doc: the steady state under constant
    velocity is on the target, moving with it, for any frequency and damping ratio). A point
    whose first step is not finite (a degenerate pose's target) starts at rest."""
    x = np.array(t0, dtype=np.float64, copy=True)
    if t1 is None:
        return x, np.zeros_like(x)
    v = (np.asarray(t1, dtype=np.float64) - x) / h  # the same expression as a step's target velocity
    v[~np.isfinite(v).all(axis=-1)] = 0.0
    return x, v


def axis_length(points: np.ndarray) -> np.ndarray:
    """The length of an axis' control polygon: points (..., n, 3) → (...)."""
    return np.linalg.norm(np.diff(points, axis=-2), axis=-1).sum(axis=-1)


def bounded(offset: np.ndarray, length, bound: float = tol.JIGGLE_BOUND,
            knee: float = tol.JIGGLE_BOUND_KNEE) -> np.ndarray:
    """Offsets (..., 3) softly clamped to ``bound`` times ``length`` (broadcast against
    offset's (...)): unchanged up to ``knee`` of the bound (the same bytes), then
    ``K + (B - K) tanh((r - K) / (B - K))`` along the same direction (module doc). An
    offset whose bound is not positive and finite (a degenerate axis) is 0: on the target."""
    offset = np.asarray(offset, dtype=np.float64)
    b = bound * np.broadcast_to(np.asarray(length, dtype=np.float64), offset.shape[:-1])
    k = knee * b
    r = np.sqrt(np.einsum("...c,...c->...", offset, offset))
    ok = np.isfinite(b) & (b > 0.0)
    over = ok & (r > k)
    if not over.any() and ok.all():
        return offset
    out = np.where(ok[..., None], offset, 0.0)
    rb, kb, ro = b[over], k[over], r[over]
    soft = kb + (rb - kb) * np.tanh((ro - kb) / (rb - kb))
    out[over] = offset[over] * (soft / ro)[:, None]
    return out


def energy(e: np.ndarray, de: np.ndarray, omega) -> np.ndarray:
    """The oscillator's energy per unit mass, ``(|e'|^2 + omega^2 |e|^2) / 2``: offsets e and
    their rates de (..., 3), omega broadcast against (...) → (...)."""
    return 0.5 * (np.einsum("...c,...c->...", de, de) + np.asarray(omega) ** 2 * np.einsum("...c,...c->...", e, e))


def oscillate(x: np.ndarray, v: np.ndarray, targets: np.ndarray, phi: np.ndarray, h: float):
    """Advance every oscillator through K steps of length h: all points of all muscles at once.

    x, v : (P, 3) positions and velocities at the time of ``targets[0]``;
    targets : (K + 1, P, 3) kinematic targets at the start and at the end of every step
    (linear in time between them); phi : (K, P, 2, 2) each point's step matrix per step.
    Returns the positions (K, P, 3) at the end of every step and the final (x, v). A point
    whose step is not finite (a degenerate pose's target) is put at rest on its target, so
    the frames after it are not poisoned."""
    k_steps = phi.shape[0]
    out = np.empty((k_steps,) + x.shape)
    for k in range(k_steps):
        t0, t1 = targets[k], targets[k + 1]
        vt = (t1 - t0) / h  # the target's velocity over the step
        e, de = x - t0, v - vt
        p = phi[k]
        e1 = p[:, 0, 0, None] * e + p[:, 0, 1, None] * de
        de1 = p[:, 1, 0, None] * e + p[:, 1, 1, None] * de
        x, v = t1 + e1, vt + de1
        bad = ~(np.isfinite(x).all(axis=-1) & np.isfinite(v).all(axis=-1))
        if bad.any():
            x[bad], v[bad] = t1[bad], 0.0
        out[k] = x
    return out, x, v
