"""B-spline bases: partition of unity, end interpolation, derivatives, periodic closure.

References are independent of axdf: scipy's ``BSpline`` for clamped and periodic bases,
central finite differences for derivatives.
"""
from __future__ import annotations

import numpy as np
import pytest
from scipy.interpolate import BSpline

from axdf_cli.model import bspline

CLAMPED_CASES = [(3, 2), (4, 2), (5, 2), (9, 2), (6, 3), (12, 3), (4, 1)]


def _params(rng, n_random=200):
    return np.concatenate([np.linspace(0.0, 1.0, 101), rng.uniform(0.0, 1.0, n_random)])


def _off_knots(knots, t, margin):
    """Parameters at least ``margin`` away from every knot (where derivatives are smooth)."""
    d = np.abs(t[:, None] - np.unique(knots)[None, :]).min(axis=1)
    return t[d > margin]


# ----------------------------------------------------------------------------- clamped


@pytest.mark.parametrize("n,k", CLAMPED_CASES)
def test_clamped_knots_shape_and_ends(n, k):
    knots = bspline.clamped_knots(n, k)
    assert knots.shape == (n + k + 1,)
    np.testing.assert_array_equal(knots[: k + 1], 0.0)
    np.testing.assert_array_equal(knots[-k - 1:], 1.0)
    assert np.all(np.diff(knots) >= 0)
    np.testing.assert_allclose(np.diff(knots[k:-k]), 1.0 / (n - k), rtol=0, atol=1e-15)


def test_clamped_knots_refuses_too_few_points():
    with pytest.raises(ValueError, match="more than 2"):
        bspline.clamped_knots(2, 2)


@pytest.mark.parametrize("n,k", CLAMPED_CASES)
def test_clamped_partition_of_unity(n, k):
    rng = np.random.default_rng(1)
    t = _params(rng)
    b = bspline.basis_matrix(bspline.clamped_knots(n, k), k, t)
    assert b.shape == (len(t), n)
    assert np.all(b >= -1e-15)
    np.testing.assert_allclose(b.sum(axis=1), 1.0, rtol=0, atol=1e-14)
    # derivatives of a partition of unity sum to zero
    for d in range(1, k + 1):
        db = bspline.basis_matrix(bspline.clamped_knots(n, k), k, t, d)
        scale = np.abs(db).max()
        np.testing.assert_allclose(db.sum(axis=1), 0.0, rtol=0, atol=1e-12 * scale)


@pytest.mark.parametrize("n,k", CLAMPED_CASES)
def test_clamped_matches_scipy(n, k):
    rng = np.random.default_rng(2)
    knots = bspline.clamped_knots(n, k)
    t = _params(rng)
    t = t[t < 1.0]  # scipy's last span is half-open
    ref = BSpline(knots, np.eye(n), k)
    for d in range(0, k + 1):
        got = bspline.basis_matrix(knots, k, t, d)
        want = ref.derivative(d)(t) if d else ref(t)
        t_ok = _off_knots(knots, t, 1e-9) if d == k else t  # the top derivative jumps at knots
        mask = np.isin(t, t_ok)
        np.testing.assert_allclose(got[mask], want[mask], rtol=0, atol=1e-11 * max(1.0, np.abs(want).max()))


@pytest.mark.parametrize("n,k", CLAMPED_CASES)
def test_clamped_end_interpolation(n, k):
    rng = np.random.default_rng(3)
    knots = bspline.clamped_knots(n, k)
    b = bspline.basis_matrix(knots, k, [0.0, 1.0])
    np.testing.assert_array_equal(b[0], np.eye(n)[0])
    np.testing.assert_array_equal(b[1], np.eye(n)[-1])
    p = rng.normal(size=(n, 3))
    c = b @ p
    np.testing.assert_allclose(c[0], p[0], rtol=0, atol=1e-15)
    np.testing.assert_allclose(c[1], p[-1], rtol=0, atol=1e-15)
    # the end tangents point along the first and last legs of the control polygon
    d = bspline.basis_matrix(knots, k, [0.0, 1.0], 1) @ p
    leg0, leg1 = p[1] - p[0], p[-1] - p[-2]
    np.testing.assert_allclose(np.cross(d[0], leg0), 0.0, atol=1e-12)
    np.testing.assert_allclose(np.cross(d[1], leg1), 0.0, atol=1e-12)
    assert d[0] @ leg0 > 0 and d[1] @ leg1 > 0


def test_clamped_parameters_outside_are_clamped():
    knots = bspline.clamped_knots(5, 2)
    b = bspline.basis_matrix(knots, 2, [-0.5, 1.5])
    np.testing.assert_array_equal(b, bspline.basis_matrix(knots, 2, [0.0, 1.0]))


@pytest.mark.parametrize("n,k", [(3, 2), (5, 2), (9, 2), (6, 3)])
def test_clamped_first_derivative_matches_central_differences(n, k):
    rng = np.random.default_rng(4)
    knots = bspline.clamped_knots(n, k)
    h = 1e-6
    t = _off_knots(knots, rng.uniform(0.01, 0.99, 300), 2 * h)
    fd = (bspline.basis_matrix(knots, k, t + h) - bspline.basis_matrix(knots, k, t - h)) / (2 * h)
    d1 = bspline.basis_matrix(knots, k, t, 1)
    # truncation h^2 B''' / 6 plus rounding eps/h
    np.testing.assert_allclose(d1, fd, rtol=0, atol=1e-7 * np.abs(d1).max())


@pytest.mark.parametrize("n,k", [(3, 2), (5, 2), (9, 2), (6, 3)])
def test_clamped_second_derivative_matches_central_differences(n, k):
    rng = np.random.default_rng(5)
    knots = bspline.clamped_knots(n, k)
    h = 1e-4
    t = _off_knots(knots, rng.uniform(0.01, 0.99, 300), 2 * h)
    b = lambda x: bspline.basis_matrix(knots, k, x)  # noqa: E731
    fd = (b(t + h) - 2 * b(t) + b(t - h)) / h**2
    d2 = bspline.basis_matrix(knots, k, t, 2)
    np.testing.assert_allclose(d2, fd, rtol=0, atol=1e-6 * np.abs(d2).max())
    # and as the central difference of the first derivative
    db = lambda x: bspline.basis_matrix(knots, k, x, 1)  # noqa: E731
    fd1 = (db(t + h) - db(t - h)) / (2 * h)
    np.testing.assert_allclose(d2, fd1, rtol=0, atol=1e-6 * np.abs(d2).max())


def test_derivative_above_degree_is_zero():
    knots = bspline.clamped_knots(5, 2)
    np.testing.assert_array_equal(bspline.basis_matrix(knots, 2, np.linspace(0, 1, 7), 3), 0.0)


def test_quadratic_curve_reproduces_a_line_with_collinear_even_points():
    """The paper's default axis: 5 evenly spaced collinear points give a uniformly
    parametrised straight segment (quadratic B-splines reproduce linear functions)."""
    knots = bspline.clamped_knots(5, 2)
    # Greville abscissae of the clamped quadratic: averages of consecutive inner knots
    greville = 0.5 * (knots[1:-2] + knots[2:-1])
    p = np.stack([greville, 2 * greville, -greville], axis=1)
    t = np.linspace(0, 1, 41)
    c = bspline.basis_matrix(knots, 2, t) @ p
    np.testing.assert_allclose(c, np.stack([t, 2 * t, -t], axis=1), rtol=0, atol=1e-15)


# ----------------------------------------------------------------------------- periodic


@pytest.mark.parametrize("n", [3, 5, 8, 11])
def test_periodic_partition_of_unity(n):
    rng = np.random.default_rng(6)
    v = np.concatenate([np.linspace(0, 1, 97), rng.uniform(0, 1, 200)])
    b = bspline.periodic_quadratic_basis(n, v)
    assert b.shape == (len(v), n)
    assert np.all(b >= 0.0)
    np.testing.assert_allclose(b.sum(axis=1), 1.0, rtol=0, atol=1e-15)


@pytest.mark.parametrize("n", [3, 5, 8, 11])
def test_periodic_matches_scipy_uniform_bspline(n):
    """Closed uniform quadratic = a uniform B-spline with knots (i - 2)/n whose basis
    function i drives control point i mod n."""
    rng = np.random.default_rng(7)
    v = rng.uniform(0, 1, 300)
    knots = (np.arange(n + 5) - 2.0) / n
    ref_open = BSpline.design_matrix(v, knots, 2).toarray()  # (S, n + 2)
    ref = np.zeros((len(v), n))
    for i in range(ref_open.shape[1]):
        ref[:, i % n] += ref_open[:, i]
    np.testing.assert_allclose(bspline.periodic_quadratic_basis(n, v), ref, rtol=0, atol=1e-14)


@pytest.mark.parametrize("n", [5, 8])
def test_periodic_closure_and_continuity(n):
    rng = np.random.default_rng(8)
    p = rng.normal(size=(n, 3))
    curve = lambda v: bspline.periodic_quadratic_basis(n, v) @ p  # noqa: E731
    # closure: v = 1 is v = 0, and the curve wraps for any real v
    np.testing.assert_array_equal(bspline.periodic_quadratic_basis(n, [1.0]),
                                  bspline.periodic_quadratic_basis(n, [0.0]))
    np.testing.assert_allclose(curve([0.3, 1.3, -0.7]), np.repeat(curve([0.3]), 3, axis=0), rtol=0, atol=1e-14)
    # C0 and C1 at every segment joint, the seam v = 0 = 1 included
    eps, h = 1e-9, 1e-6
    joints = np.arange(n) / n
    left, right = joints - eps, joints + eps
    np.testing.assert_allclose(curve(left), curve(right), rtol=0, atol=1e-7)
    d_left = (curve(joints - h) - curve(joints - 2 * h)) / h
    d_right = (curve(joints + 2 * h) - curve(joints + h)) / h
    # one-sided differences are O(h) accurate; the jump of a C1 curve's derivative is 0
    np.testing.assert_allclose(d_left, d_right, rtol=0, atol=1e-4 * np.abs(p).max() * n**2)


def test_periodic_joint_is_the_edge_midpoint():
    n = 8
    p = np.random.default_rng(9).normal(size=(n, 2))
    c = bspline.periodic_quadratic_basis(n, np.arange(n) / n) @ p
    np.testing.assert_allclose(c, 0.5 * (p + np.roll(p, -1, axis=0)), rtol=0, atol=1e-15)


# ----------------------------------------------------------------------------- rational


def test_rational_partition_of_unity_and_weights():
    rng = np.random.default_rng(10)
    n = 6
    knots = bspline.clamped_knots(n, 2)
    t = rng.uniform(0, 1, 200)
    b = bspline.basis_matrix(knots, 2, t)
    w = rng.uniform(0.2, 5.0, n)
    r = bspline.rational(b, w)
    assert np.all(r >= 0)
    np.testing.assert_allclose(r.sum(axis=1), 1.0, rtol=0, atol=1e-14)
    # equal weights: the plain basis
    np.testing.assert_allclose(bspline.rational(b, np.full(n, 3.7)), b, rtol=0, atol=1e-15)
    # a heavier weight pulls the curve towards its control point
    p = rng.normal(size=(n, 3))
    tq = np.array([0.5])
    bq = bspline.basis_matrix(knots, 2, tq)
    i = int(np.argmax(bq[0]))
    w2 = np.ones(n)
    w2[i] = 10.0
    d_plain = np.linalg.norm(bq @ p - p[i])
    d_heavy = np.linalg.norm(bspline.rational(bq, w2) @ p - p[i])
    assert d_heavy < 0.5 * d_plain


def test_rational_periodic_partition_of_unity():
    rng = np.random.default_rng(11)
    b = bspline.periodic_quadratic_basis(8, rng.uniform(0, 1, 100))
    r = bspline.rational(b, rng.uniform(0.5, 2.0, 8))
    np.testing.assert_allclose(r.sum(axis=1), 1.0, rtol=0, atol=1e-14)


# ----------------------------------------------------------------------------- quadrature


def test_gauss_legendre_integrates_polynomials_exactly():
    knots = bspline.clamped_knots(5, 2)
    t, w = bspline.gauss_legendre_params(knots, 2, 8)
    assert t.shape == w.shape == (3 * 8,)
    assert np.all((t > 0) & (t < 1))
    for k in range(0, 16):  # 8 points per span integrate degree <= 15 exactly
        np.testing.assert_allclose(np.sum(w * t**k), 1.0 / (k + 1), rtol=0, atol=1e-14)


def test_arc_length_of_a_straight_axis():
    knots = bspline.clamped_knots(5, 2)
    rng = np.random.default_rng(12)
    a, b = rng.normal(size=3), rng.normal(size=3)
    p = a + np.sort(rng.uniform(0, 1, 5))[:, None] * (b - a)  # collinear, uneven, monotone
    p[0], p[-1] = a, b
    t, w = bspline.gauss_legendre_params(knots, 2, 8)
    speed = np.linalg.norm(bspline.basis_matrix(knots, 2, t, 1) @ p, axis=1)
    np.testing.assert_allclose(speed @ w, np.linalg.norm(b - a), rtol=0, atol=1e-14)
