"""The jiggle law (axdf_cli/model/jiggle.py): the exact oscillator step against scipy's matrix
exponential, the textbook step response, frame-rate independence, energy, weights and the
muscle file's ``jiggle:`` key."""
from __future__ import annotations

import numpy as np
import pytest
import scipy.linalg
from hypothesis import given, settings, strategies as st

from axdf_cli.errors import InputError
from axdf_cli.model import jiggle
from axdf_cli.specs import parse_muscle_text


def _expm_reference(omega: float, zeta: float, h: float) -> np.ndarray:
    a = np.array([[0.0, 1.0], [-omega * omega, -2.0 * zeta * omega]])
    return scipy.linalg.expm(a * h)


@pytest.mark.parametrize("zeta", [0.0, 0.05, 0.3, 0.9, 1.0 - 1e-7, 1.0, 1.0 + 1e-7, 1.5, 4.0, 60.0])
@pytest.mark.parametrize("hz", [0.5, 5.0, 40.0, 400.0])
@pytest.mark.parametrize("fps", [24, 60, 120, 1000])
def test_step_is_the_matrix_exponential(zeta, hz, fps):
    omega, h = 2 * np.pi * hz, 1.0 / fps
    ref = _expm_reference(omega, zeta, h)
    got = jiggle.step_matrices(np.array([omega]), np.array([zeta]), h)[0]
    assert np.abs(got - ref).max() <= 1e-10 * max(1.0, np.abs(ref).max())


def test_step_matrices_batch_equals_one_at_a_time():
    rng = np.random.default_rng(3)
    w = 2 * np.pi * rng.uniform(0.5, 50, 200)
    z = rng.uniform(0, 5, 200)
    batch = jiggle.step_matrices(w, z, 1 / 60)
    one = np.stack([jiggle.step_matrices(w[i:i + 1], z[i:i + 1], 1 / 60)[0] for i in range(200)])
    assert np.array_equal(batch, one)  # same bytes whatever the batch (--jobs splits muscles)


def _ramp_then_hold(fps: float, seconds: float = 3.0, ramp: float = 0.2, distance: float = 0.05):
    """Times (K+1,) and a 1-point target (K+1, 1, 3) that moves at constant speed for ``ramp``
    seconds and stops dead (a hinge that bends and stops), sampled at fps."""
    t = np.arange(int(round(seconds * fps)) + 1) / fps
    x = distance * np.clip(t / ramp, 0.0, 1.0)
    return t, np.stack([x, np.zeros_like(x), np.zeros_like(x)], axis=-1)[:, None, :]


def _run(targets, hz, zeta, fps):
    omega, z = jiggle.parameters(jiggle.JiggleSpec(hz, zeta), np.zeros(len(targets) - 1))
    phi = jiggle.step_matrices(omega, z, 1.0 / fps)[:, None]  # (K, 1, 2, 2)
    out, _, _ = jiggle.oscillate(targets[0].copy(), np.zeros((1, 3)), targets, phi, 1.0 / fps)
    return np.concatenate([targets[:1], out])[:, 0, 0] - targets[:, 0, 0]  # offset e(t) along the motion


def _extrema(t, e):
    """Times and values of the offset's extrema (parabola through each discrete extremum)."""
    i = np.nonzero((np.abs(e[1:-1]) >= np.abs(e[:-2])) & (np.abs(e[1:-1]) > np.abs(e[2:])))[0] + 1
    y0, y1, y2 = e[i - 1], e[i], e[i + 1]
    den = y0 - 2 * y1 + y2
    d = np.where(den != 0, 0.5 * (y0 - y2) / np.where(den != 0, den, 1), 0.0)
    return t[i] + d * (t[1] - t[0]), y1 - 0.25 * (y0 - y2) * d


@pytest.mark.parametrize("hz,zeta", [(4.0, 0.1), (6.0, 0.25), (10.0, 0.4)])
def test_ring_after_a_stop_has_the_set_frequency_and_damping(hz, zeta):
    fps = 1000.0
    t, target = _ramp_then_hold(fps)
    e = _run(target, hz, zeta, fps)
    after = t > 0.2
    te, ye = _extrema(t[after], e[after])
    keep = np.abs(ye) > 1e-6 * np.abs(e).max()  # above the float noise of a settled ring
    te, ye = te[keep], ye[keep]
    assert len(te) >= 3
    half_periods = np.diff(te)
    damped = hz * np.sqrt(1 - zeta ** 2)
    assert np.allclose(half_periods, 0.5 / damped, rtol=2e-3)
    ratios = np.abs(ye[1:] / ye[:-1])
    assert np.allclose(ratios, np.exp(-np.pi * zeta / np.sqrt(1 - zeta ** 2)), rtol=5e-3)
    assert np.all(np.sign(ye[1:]) == -np.sign(ye[:-1]))  # it rings about the target
    assert abs(e[-1]) < 1e-3 * np.abs(e).max()  # and settles


@pytest.mark.parametrize("zeta", [1.0, 3.0])
def test_critical_and_over_damped_do_not_ring(zeta):
    t, target = _ramp_then_hold(240.0)
    e = _run(target, 5.0, zeta, 240.0)
    stopped = e[t >= 0.2]
    # the lag left at the stop may cross the target once (its velocity carries it), then the
    # offset creeps back without ringing: one sign change at most, monotone after its extremum
    signs = np.sign(stopped[np.abs(stopped) > 1e-12])
    assert np.count_nonzero(np.diff(signs)) <= 1
    peak = np.argmax(np.abs(stopped))
    assert np.all(np.diff(np.abs(stopped[peak:])) <= 1e-15)


@pytest.mark.parametrize("zeta", [0.15, 0.5, 1.0])
def test_same_motion_at_30_60_120_fps(zeta):
    """The step is exact: frame rates differ only in how finely the (same) target is sampled."""
    runs = {}
    for fps in (30, 60, 120):
        t, target = _ramp_then_hold(float(fps), seconds=2.0, ramp=0.2)
        runs[fps] = (t, _run(target, 4.0, zeta, float(fps)))
    t30, e30 = runs[30]
    peak = np.abs(runs[120][1]).max()
    for fps in (60, 120):
        t, e = runs[fps]
        step = fps // 30
        assert np.allclose(t[::step], t30)
        assert np.abs(e[::step] - e30).max() <= 0.05 * peak


@settings(max_examples=300, deadline=None, derandomize=True)
@given(hz=st.floats(0.1, 200.0), zeta=st.floats(0.0, 20.0), fps=st.sampled_from([24, 30, 60, 120, 240]),
       seed=st.integers(0, 2 ** 32 - 1))
def test_energy_never_grows_on_a_random_motion(hz, zeta, fps, seed):
    """Along a random target motion (new velocity every frame), the free oscillation's energy
    E = (|e'|^2 + w^2 |e|^2) / 2 never grows inside a step (it is conserved when zeta = 0);
    only the bone's change of velocity between frames changes it. Once the motion stops, the
    energy decays monotonically."""
    rng = np.random.default_rng(seed)
    h = 1.0 / fps
    k = 40
    targets = np.concatenate([np.cumsum(rng.normal(0, 0.01, (k + 1, 5, 3)), axis=0),
                              np.repeat(np.zeros((1, 5, 3)), 20, axis=0)])
    targets[k + 1:] = targets[k]  # the motion stops at step k
    omega, z = jiggle.parameters(jiggle.JiggleSpec(hz, zeta), np.zeros(len(targets) - 1))
    phi = jiggle.step_matrices(omega, z, h)[:, None].repeat(5, axis=1)
    x, v = targets[0].copy(), np.zeros((5, 3))
    after_stop = []
    for s in range(len(targets) - 1):
        vt = (targets[s + 1] - targets[s]) / h
        e0 = jiggle.energy(x - targets[s], v - vt, omega[s])
        _, x, v = jiggle.oscillate(x, v, targets[s:s + 2], phi[s:s + 1], h)
        e1 = jiggle.energy(x - targets[s + 1], v - vt, omega[s])
        scale = max(float(e0.max()), 1e-300)
        assert np.all(e1 <= e0 + 1e-9 * scale)
        if zeta == 0.0:
            assert np.allclose(e1, e0, rtol=1e-9, atol=1e-12 * scale)
        if s >= k:
            after_stop.append(e1)
    after_stop = np.array(after_stop)
    assert np.all(np.diff(after_stop, axis=0) <= 1e-9 * max(after_stop.max(), 1e-300))


def test_weights_hold_the_ends():
    for n in (3, 5, 16, 48):
        w = jiggle.control_weights(None, n)
        assert w[0] == 0.0 and w[-1] == 0.0
        assert np.all(w[1:-1] > 0) and np.all(w <= 1.0)
        assert np.allclose(w, w[::-1])  # the default profile is symmetric
    g = jiggle.greville(5)
    assert np.allclose(g, [0, 1 / 6, 1 / 2, 5 / 6, 1])
    w = jiggle.control_weights((0.0, 1.0, 1.0, 0.0), 5)
    assert np.allclose(w, np.interp(g, [0, 1 / 3, 2 / 3, 1], [0, 1, 1, 0]))


def test_tension_stiffens_and_damps():
    spec = jiggle.JiggleSpec(5.0, 0.2, tensed_frequency=10.0, tensed_damping_ratio=0.6)
    omega, zeta = jiggle.parameters(spec, np.array([0.0, 0.5, 1.0]))
    assert np.allclose(omega / (2 * np.pi), [5.0, np.sqrt(0.5 * 25 + 0.5 * 100), 10.0])
    assert np.allclose(zeta, [0.2, 0.4, 0.6])
    same = jiggle.parameters(jiggle.JiggleSpec(5.0, 0.2), np.array([0.0, 1.0]))
    assert np.allclose(same[0], 2 * np.pi * 5.0) and np.allclose(same[1], 0.2)


MUSCLE = """muscle: m
axis:
  - {bone: a, at: [0, 0, 0]}
  - {bone: a, at: [0, 0, 0.1]}
  - {bone: a, at: [0, 0, 0.2]}
"""


def test_jiggle_key_is_read():
    (spec,) = parse_muscle_text(MUSCLE + "jiggle: {frequency: 5, damping_ratio: 0.3, weight: [0, 1, 0.5, 0],\n"
                                         "         tensed: {frequency: 9, damping_ratio: 0.6}}\n", "m.yaml")
    assert spec.jiggle == jiggle.JiggleSpec(5.0, 0.3, (0.0, 1.0, 0.5, 0.0), 9.0, 0.6)
    (plain,) = parse_muscle_text(MUSCLE, "m.yaml")
    assert plain.jiggle is None


@pytest.mark.parametrize("text,where,words", [
    ("jiggle: {damping_ratio: 0.3}", "6:9", "needs 'frequency'"),
    ("jiggle: {frequency: 0, damping_ratio: 0.3}", "6:21", "frequency must be in (0.0, 1000.0]"),
    ("jiggle: {frequency: 5, damping_ratio: -1}", "6:39", "damping_ratio must be in [0.0, 100.0]"),
    ("jiggle: {frequency: 5, damping_ratio: 0.3, weight: [0, 1, 0.5]}", "6:59", "first and last weights are 0"),
    ("jiggle: {frequency: 5, damping_ratio: 0.3, weight: [0]}", "6:52", "at least 2"),
    ("jiggle: {frequency: 5, damping_ratio: 0.3, tensed: {frequncy: 9}}", "6:53", "did you mean 'frequency'"),
    ("jiggle: {frequency: 5, damping: 0.3}", "6:24", "did you mean 'damping_ratio'"),
    ("jiggle: 5", "6:9", "jiggle must be a mapping"),
])
def test_jiggle_errors_have_positions(text, where, words):
    with pytest.raises(InputError) as e:
        parse_muscle_text(MUSCLE + text + "\n", "m.yaml")
    assert str(e.value).startswith(f"m.yaml:{where}:"), str(e.value)
    assert words in str(e.value), str(e.value)


def test_a_target_that_is_not_finite_stays_one_frame():
    """A degenerate pose (a non-finite target) is that frame's problem only: the oscillator
    restarts at rest on the next finite target."""
    t, target = _ramp_then_hold(60.0, seconds=1.0)
    target = target.copy()
    target[20, 0, 1] = np.nan
    omega, z = jiggle.parameters(jiggle.JiggleSpec(4.0, 0.2), np.zeros(len(target) - 1))
    phi = jiggle.step_matrices(omega, z, 1 / 60)[:, None]
    out, x, v = jiggle.oscillate(target[0].copy(), np.zeros((1, 3)), target, phi, 1 / 60)
    finite = np.isfinite(out).all(axis=(1, 2))
    assert not finite[19] and finite[:19].all() and finite[21:].all()  # out[k] is frame k + 1
    assert np.isfinite(x).all() and np.isfinite(v).all()


def test_bound_is_a_soft_clamp_relative_to_the_length():
    """``bounded``: the same offsets (bytes) below the knee; above it, the same direction and a
    length that rises monotonically towards the bound, never reaching it; value, slope and
    curvature continuous at the knee (no kink)."""
    from axdf_cli import tolerances as tol

    b, k = tol.JIGGLE_BOUND, tol.JIGGLE_BOUND_KNEE
    assert 0.0 < k < 1.0 and 0.0 < b < 1.0
    length = 0.4
    rng = np.random.default_rng(11)
    small = rng.normal(size=(50, 3))
    small *= (rng.uniform(0, k * b * length, 50) / np.linalg.norm(small, axis=1))[:, None]
    assert np.array_equal(jiggle.bounded(small, length), small)
    direction = np.array([0.6, 0.0, 0.8])
    r = np.linspace(0.0, 50.0, 200001) * length  # up to 50 lengths
    got = np.linalg.norm(jiggle.bounded(r[:, None] * direction, np.full(len(r), length)), axis=1)
    eps = 1e-12 * b * length  # rounding of the rescaled vector's length
    assert np.all(got <= b * length + eps) and np.all(np.diff(got) >= -eps)
    assert got[-1] >= (1 - 1e-9) * b * length
    assert np.allclose(jiggle.bounded(3.0 * length * direction[None], length)[0] / got[-1], direction)
    # slope and curvature on both sides of the knee, by finite differences
    f = lambda x: float(np.linalg.norm(jiggle.bounded(np.array([x * direction]), length)[0]))  # noqa: E731
    kr, d = k * b * length, 1e-5 * length
    left = (f(kr) - f(kr - d)) / d, (f(kr) - 2 * f(kr - d) + f(kr - 2 * d)) / d ** 2
    right = (f(kr + d) - f(kr)) / d, (f(kr + 2 * d) - 2 * f(kr + d) + f(kr)) / d ** 2
    assert abs(left[0] - 1.0) < 1e-6 and abs(right[0] - 1.0) < 1e-3
    assert abs(right[1]) < 1e-2 / length  # (tanh'' = 0 at 0: curvature 0 on both sides)


def test_bound_holds_a_degenerate_axis_on_its_target():
    off = np.array([[0.1, 0.0, 0.0], [0.0, 0.2, 0.0], [0.0, 0.0, 0.15]])
    got = jiggle.bounded(off, np.array([0.0, np.nan, 1.0]))
    assert np.array_equal(got[:2], np.zeros((2, 3))) and np.array_equal(got[2], off[2])
