"""Rotation-minimizing frames by double reflection (Wang et al. 2008).

Checks: orthonormal frames; no rotation about the tangent between samples (the RMF
property); agreement with the analytic RMF of a helix and with a 16x denser double
reflection on the demo muscles' axes at extreme poses; no flips on curves whose tangent
sweeps every direction.
"""
from __future__ import annotations

import numpy as np
import pytest

from axdf_cli.model import bspline, rmf
from axdf_cli import tolerances as tol
from axdf_cli.model.skeleton import forward_kinematics

from conftest import demo_extreme_coordinates, random_rigid

HELIX_A, HELIX_B = 1.0, 0.3  # radius and pitch/(2 pi) of the test helix
DENSER = 16


def helix(turns: float, per_quarter: int):
    """Samples of (a cos th, a sin th, b th): x, unit tangent T, Frenet N, B and th."""
    a, b = HELIX_A, HELIX_B
    c = np.hypot(a, b)
    th = np.linspace(0.0, 2 * np.pi * turns, int(round(4 * turns * per_quarter)) + 1)
    x = np.stack([a * np.cos(th), a * np.sin(th), b * th], axis=1)
    t = np.stack([-a * np.sin(th), a * np.cos(th), np.full_like(th, b)], axis=1) / c
    n = np.stack([-np.cos(th), -np.sin(th), np.zeros_like(th)], axis=1)
    return th, x, t, n, np.cross(t, n)


def spherical_spiral(n: int, k: float = 9.0, denser: int = 1):
    """A curve whose unit tangent runs along a spiral over the whole sphere, from +Z through
    every horizontal direction to -Z: (n, 3) positions and tangents. Positions integrate the
    tangent (trapezoid rule on a grid ``denser`` times finer, then subsampled), so that
    samples of different densities lie on the same curve."""
    m = (n - 1) * 64 + 1
    u = np.linspace(0.0, 1.0, m)
    ph, th = np.pi * u, 2 * np.pi * k * u
    t = np.stack([np.sin(ph) * np.cos(th), np.sin(ph) * np.sin(th), np.cos(ph)], axis=1)
    x = np.concatenate([np.zeros((1, 3)), np.cumsum(0.5 * (t[1:] + t[:-1]), axis=0) / (m - 1)])
    step = 64 // denser
    return x[::step], t[::step]


def angle_between(a, b):
    """Unsigned angle between unit vectors (..., 3), accurate for small angles."""
    return 2.0 * np.arcsin(np.clip(0.5 * np.linalg.norm(a - b, axis=-1), 0.0, 1.0))


def assert_orthonormal(t, r, atol=1e-12):
    s = np.cross(t, r)
    frames = np.stack([t, r, s], axis=-1)  # (..., 3, 3) columns T, R, S
    eye = np.broadcast_to(np.eye(3), frames.shape)
    np.testing.assert_allclose(np.swapaxes(frames, -1, -2) @ frames, eye, rtol=0, atol=atol)
    np.testing.assert_allclose(np.linalg.det(frames), 1.0, rtol=0, atol=atol)


# ----------------------------------------------------------------------------- helix


def test_helix_frames_are_orthonormal():
    _, x, t, n, _ = helix(3, tol.RMF_SAMPLES_PER_SPAN)
    r = rmf.propagate(x[None], t[None], n[None, 0])[0]
    assert_orthonormal(t, r, atol=1e-12)


def test_helix_matches_the_analytic_rmf():
    """On a helix the RMF turns against the Frenet frame at the rate of the torsion:
    U = cos(phi) N + sin(phi) B with phi = -tau * s = -b th / c."""
    th, x, t, n, b = helix(2, tol.RMF_SAMPLES_PER_SPAN)  # a quarter turn per "span"
    r = rmf.propagate(x[None], t[None], n[None, 0])[0]
    phi = -HELIX_B * th / np.hypot(HELIX_A, HELIX_B)
    u = np.cos(phi)[:, None] * n + np.sin(phi)[:, None] * b
    err = np.abs(rmf.signed_angle(r, u, t))
    assert err.max() < tol.RMF_MAX_FRAME_ERROR_RAD
    # and the total rotation against Frenet is large, so this is not a vacuous check
    assert abs(phi[-1]) > 3.0


def test_helix_error_against_denser_reference():
    per = tol.RMF_SAMPLES_PER_SPAN
    _, x, t, n, _ = helix(2, per)
    _, xd, td, nd, _ = helix(2, per * DENSER)
    r = rmf.propagate(x[None], t[None], n[None, 0])[0]
    rd = rmf.propagate(xd[None], td[None], nd[None, 0])[0][::DENSER]
    np.testing.assert_allclose(xd[::DENSER], x, rtol=0, atol=1e-12)
    assert np.abs(rmf.signed_angle(r, rd, t)).max() < tol.RMF_MAX_FRAME_ERROR_RAD


def test_helix_has_no_rotation_about_the_tangent():
    """omega . T = (dR/ds) . S is zero for an RMF; the Frenet frame has it equal to the
    torsion. Measured per step as (R_i+1 - R_i) . (S_i + S_i+1)/2 / |x_i+1 - x_i|."""
    _, x, t, n, b = helix(2, tol.RMF_SAMPLES_PER_SPAN)
    r = rmf.propagate(x[None], t[None], n[None, 0])[0]
    s = np.cross(t, r)
    ds = np.linalg.norm(np.diff(x, axis=0), axis=1)
    w_rmf = np.einsum("ic,ic->i", np.diff(r, axis=0), 0.5 * (s[1:] + s[:-1])) / ds
    w_frenet = np.einsum("ic,ic->i", np.diff(n, axis=0), 0.5 * (b[1:] + b[:-1])) / ds
    tau = HELIX_B / (HELIX_A**2 + HELIX_B**2)
    np.testing.assert_allclose(np.abs(w_frenet), tau, rtol=1e-2)
    assert np.abs(w_rmf).max() < 1e-3 * tau


# ----------------------------------------------------------------------------- no flips


def _assert_no_flip(x, t, r):
    """For an RMF |dR| <= |dT| (R' = -(R.T') T): R never turns faster than the tangent."""
    ang_r = angle_between(r[1:], r[:-1])
    ang_t = angle_between(t[1:], t[:-1])
    assert np.all(ang_r <= ang_t * (1 + 1e-3) + 1e-12), float(np.max(ang_r - ang_t))
    assert ang_r.max() < 0.1


def test_helix_no_flip():
    _, x, t, n, _ = helix(5, tol.RMF_SAMPLES_PER_SPAN)
    r = rmf.propagate(x[None], t[None], n[None, 0])[0]
    _assert_no_flip(x, t, r)


def test_spherical_spiral_no_flip_and_orthonormal():
    x, t = spherical_spiral(1001)
    # the tangent passes close to every world axis direction, both signs
    for axis in np.concatenate([np.eye(3), -np.eye(3)]):
        assert (t @ axis).max() > 0.95
    r0 = rmf.any_perpendicular(t[:1])
    r = rmf.propagate(x[None], t[None], r0)[0]
    assert np.all(np.isfinite(r))
    assert_orthonormal(t, r, atol=1e-12)
    _assert_no_flip(x, t, r)
    # converged: agrees with a 16x denser reference
    xd, td = spherical_spiral(1001, denser=DENSER)
    np.testing.assert_array_equal(xd[::DENSER], x)
    rd = rmf.propagate(xd[None], td[None], r0)[0][::DENSER]
    assert np.abs(rmf.signed_angle(r, rd, t)).max() < tol.RMF_MAX_FRAME_ERROR_RAD


def test_repeated_samples_do_not_produce_nan():
    """Coincident consecutive samples (a degenerate axis) must not give NaN frames."""
    _, x, t, n, _ = helix(0.5, 8)
    x = np.repeat(x, 2, axis=0)
    t = np.repeat(t, 2, axis=0)
    r = rmf.propagate(x[None], t[None], n[None, 0])[0]
    assert np.all(np.isfinite(r))
    assert_orthonormal(t, r, atol=1e-12)


def test_reflect_step_over_a_rounding_noise_step_keeps_the_frame():
    """Two samples a few ulps apart at the same tangent: the frame must not turn. (Axis-
    aligned vectors keep the arithmetic exact, so the noise step stays normal to t0.)"""
    eye = np.eye(3)
    x0 = np.array([0.3, -1.7, 2.9])
    for i in range(3):
        for sign in (1.0, -1.0):
            t0 = sign * eye[i]
            r0, s0 = eye[(i + 1) % 3], np.cross(sign * eye[i], eye[(i + 1) % 3])
            for size in (3e-15, 8e-15):
                for d in (r0, (r0 + s0) / np.sqrt(2.0)):
                    r1 = rmf.reflect_step(x0, t0, r0, x0 + size * d, t0)
                    assert angle_between(r1, r0) < 1e-6, (t0, d, size, r1)


def test_propagation_is_rigidly_invariant():
    _, x, t, n, _ = helix(1, 16)
    m = random_rigid(np.random.default_rng(20), scale=3.0)
    rot, tr = m[:3, :3], m[:3, 3]
    r = rmf.propagate(x[None], t[None], n[None, 0])[0]
    r2 = rmf.propagate((x @ rot.T + tr)[None], (t @ rot.T)[None], (n[0] @ rot.T)[None])[0]
    np.testing.assert_allclose(r2, r @ rot.T, rtol=0, atol=1e-12)


def test_helper_vectors():
    rng = np.random.default_rng(21)
    t = rng.normal(size=(500, 3))
    t /= np.linalg.norm(t, axis=1, keepdims=True)
    t[:6] = np.concatenate([np.eye(3), -np.eye(3)])
    p = rmf.any_perpendicular(t)
    np.testing.assert_allclose(np.einsum("ic,ic->i", p, t), 0.0, atol=1e-15)
    np.testing.assert_allclose(np.linalg.norm(p, axis=1), 1.0, atol=1e-15)
    ang = rng.uniform(-np.pi + 1e-6, np.pi, 500)
    q = np.cos(ang)[:, None] * p + np.sin(ang)[:, None] * np.cross(t, p)
    np.testing.assert_allclose(rmf.signed_angle(p, q, t), ang, rtol=0, atol=1e-12)


# ----------------------------------------------------------------------------- muscle axes


def _model_frames(model, world, per_span):
    """RMF reference vectors of a muscle's axis, sampled ``per_span`` per knot span, started
    exactly as MuscleModel starts them: (F, S, 3) T and R."""
    n = len(model.at)
    ts = np.linspace(0.0, 1.0, per_span * (n - 2) + 1)
    p = model._axis_points(world)
    b, db = bspline.basis_matrix(model.knots, 2, ts), bspline.basis_matrix(model.knots, 2, ts, 1)
    x = np.einsum("si,fic->fsc", b, p)
    d = np.einsum("si,fic->fsc", db, p)
    t = d / np.linalg.norm(d, axis=-1, keepdims=True)
    r0 = rmf.perpendicular_unit(world[:, model.origin_bone, :3, :3] @ model.r0_local, t[:, 0])
    return t, rmf.propagate(x, t, r0)


def test_model_samples_use_the_documented_density(demo):
    for m in demo.models:
        assert len(m.ts) == tol.rmf_samples(m.n_axis) + 1
    assert tol.rmf_samples(5) == tol.RMF_SAMPLES_PER_SPAN * 3
    assert tol.rmf_samples(40) == tol.RMF_SAMPLES_PER_SPAN * 6 + tol.RMF_SAMPLES_PER_EXTRA_SPAN * 32


def test_demo_axes_frame_error_at_extreme_poses(demo):
    q = demo_extreme_coordinates(demo.skel, np.random.default_rng(22))
    world = forward_kinematics(demo.skel, q)
    for m in demo.models:
        t, r = _model_frames(m, world, tol.RMF_SAMPLES_PER_SPAN)
        assert_orthonormal(t, r, atol=1e-12)
        td, rd = _model_frames(m, world, tol.RMF_SAMPLES_PER_SPAN * DENSER)
        err = np.abs(rmf.signed_angle(r, rd[:, ::DENSER], t))
        assert err.max() < tol.RMF_MAX_FRAME_ERROR_RAD, m.spec.name
        # the engine's own sampled frames agree with ours
        x_eng = np.einsum("si,fic->fsc", m.Bs, m._axis_points(world))
        assert x_eng.shape[1] == t.shape[1]


@pytest.mark.parametrize("per_span", [4, 8])
def test_coarse_sampling_of_a_bspline_axis_still_converges(demo, per_span):
    """Each span of a quadratic B-spline is a planar parabola, so double reflection is
    exact within a span; even coarse sampling matches the dense reference."""
    q = demo_extreme_coordinates(demo.skel, np.random.default_rng(23), n_random=4)
    world = forward_kinematics(demo.skel, q)
    m = demo.models[0]
    t, r = _model_frames(m, world, per_span)
    td, rd = _model_frames(m, world, per_span * DENSER)
    assert np.abs(rmf.signed_angle(r, rd[:, ::DENSER], t)).max() < tol.RMF_MAX_FRAME_ERROR_RAD
