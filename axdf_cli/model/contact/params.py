"""Contact's settings and the named groups of arrays its kernels take.

The groups are :class:`typing.NamedTuple`\\ s, which numba's compiled kernels accept as they
are: a kernel takes a few named groups, not dozens of positional arrays."""
from __future__ import annotations

from typing import NamedTuple

import numpy as np

from axdf_cli import tolerances as tol
from axdf_cli.model.muscle import ContactSpec

#: Rings within this share of a muscle's length from an end make a thick neighbour give way
#: less (none at the poles): an attachment ring holds its place (:func:`rings.point_push`).
END_FADE = 0.1
#: Columns of the ring table :func:`query.centres` fills.
CEN_COLUMNS = 13
#: Centre segments per bounding sphere in :func:`query.muscle_query`'s search.
SEG_GROUP = 4
#: The trilinear field's largest slope (:func:`query.ring_lists`).
SQRT3 = float(np.sqrt(3.0))
#: Length of :func:`query.query_in`'s output (rho, R, axis point, radial direction, segment,
#: parameter).
QUERY_SIZE = 10
#: The modes of a ring's displacement around its angle theta: the section's shift (1), its
#: shift and tilt of one side (cos, sin theta), its flattening (cos, sin 2 theta).
NMODES = 5
#: Room for each muscle's records of a pass's pulls on thick neighbours (:func:`query.work`);
#: a pass that needs more runs again with room for all.
REACTION_RECORDS = 1024


class Mesh(NamedTuple):
    """Every muscle of a frame as grids: rows off[m]:off[m + 1] of ``grid`` (U * A, 3) are
    muscle m's (nu[m] rings of na[m] points, pole rows repeated); ``cen`` (rings,
    :data:`CEN_COLUMNS`) its ring table from row coff[m] (:func:`query.centres`); ``box``
    (M, 6) the muscles' bounding boxes (lo, hi)."""

    grid: np.ndarray
    off: np.ndarray
    nu: np.ndarray
    na: np.ndarray
    cen: np.ndarray
    coff: np.ndarray
    box: np.ndarray


class Fields(NamedTuple):
    """The bone fields (:class:`fields.BoneFields`) with the frame's world to bone-local
    transforms ``inv`` (B, 4, 4): field k belongs to bone fb[k], its grid starts at fo[k]
    (3,) with spacing fh[k] and dims fd[k] (3,), its values are fv[foff[k]:foff[k + 1]]."""

    inv: np.ndarray
    fb: np.ndarray
    fo: np.ndarray
    fh: np.ndarray
    fd: np.ndarray
    foff: np.ndarray
    fv: np.ndarray


class Lists(NamedTuple):
    """What each muscle may meet, as CSR rows: its neighbours nbr[nbr_off[i]:nbr_off[i + 1]]
    (:func:`query.neighbours`) and bone fields fl[fl_off[i]:fl_off[i + 1]]
    (:func:`query.field_lists`)."""

    nbr_off: np.ndarray
    nbr: np.ndarray
    fl_off: np.ndarray
    fl: np.ndarray


class Rows(NamedTuple):
    """One muscle's (or one point's) scratch arrays for the queries: q the query
    (:data:`QUERY_SIZE`), g a gradient (6), p a push (7), actb, actm, gl, gn what a ring may
    meet (:func:`query.ring_lists`), rec the pulls on thick neighbours (:func:`rings.give_way`)."""

    q: np.ndarray
    g: np.ndarray
    p: np.ndarray
    actb: np.ndarray
    actm: np.ndarray
    gl: np.ndarray
    gn: np.ndarray
    rec: np.ndarray


class Work(NamedTuple):
    """Scratch arrays for every muscle (:func:`query.work`): row i of each of the first ten is
    muscle i's (:class:`Rows` and b (:data:`NMODES`), tab (the modes at every column of a
    ring)); react (rings, 3 :data:`NMODES` + 1) the pulls added up per ring."""

    q: np.ndarray
    g: np.ndarray
    p: np.ndarray
    b: np.ndarray
    actb: np.ndarray
    actm: np.ndarray
    gl: np.ndarray
    gn: np.ndarray
    rec: np.ndarray
    tab: np.ndarray
    react: np.ndarray


class Modes(NamedTuple):
    """What a pass of :func:`rings.ring_modes` fills: the muscles' pushes' modes ``coef`` and
    the bones' ``coefb`` (rings, :data:`NMODES`, 3), ``touched`` (M,) where a sample was
    pushed, ``buried`` (M,) the share of samples inside a bone."""

    coef: np.ndarray
    coefb: np.ndarray
    touched: np.ndarray
    buried: np.ndarray


class PushParams(NamedTuple):
    """The push's settings (:func:`rings.point_push`): the margins to keep from muscles and
    bones, the fades near a neighbour's axis (deep0, deep1, in its radii) and where two axes
    meet (sep0, sep1), the radial direction's share, the thin-against-thick range (thin0,
    thin1) and how many times over each push is asked for (tol.CONTACT_RELAX)."""

    margin_m: float
    margin_b: float
    deep0: float
    deep1: float
    sep0: float
    sep1: float
    radial_blend: float
    thin0: float
    thin1: float
    relax_m: float
    relax_b: float
    relax_r: float


def push_params(relax: tuple) -> PushParams:
    """The tolerances' push settings, each push asked for ``relax`` (muscles, bones, thick
    muscles) times over."""
    return PushParams(tol.CONTACT_MARGIN, tol.CONTACT_BONE_MARGIN, tol.CONTACT_DEEP_FADE[0], tol.CONTACT_DEEP_FADE[1],
                      tol.CONTACT_AXES_FADE[0], tol.CONTACT_AXES_FADE[1], tol.CONTACT_RADIAL_BLEND,
                      tol.CONTACT_THIN[0], tol.CONTACT_THIN[1], *(float(r) for r in relax))


def pair_shares(yields: np.ndarray) -> np.ndarray:
    """Share of an overlap that muscle i takes against j: (M, M), share[i, j] + share[j, i] = 1.

    0.5 for equal yields, growing by tol.CONTACT_SHARE_PER_LAYER per layer of difference up
    to tol.CONTACT_SHARE_MAX (a deep muscle gives way to a superficial one)."""
    d = yields[:, None] - yields[None, :]
    return np.clip(0.5 + tol.CONTACT_SHARE_PER_LAYER * d, 1.0 - tol.CONTACT_SHARE_MAX, tol.CONTACT_SHARE_MAX)


def pair_mask(names: list[str], specs: list[ContactSpec]) -> np.ndarray:
    """Which pairs collide: (M, M) bool, symmetric, False on the diagonal, within a group and
    where either muscle ignores the other."""
    m = len(names)
    ok = ~np.eye(m, dtype=bool)
    for i, s in enumerate(specs):
        for j in range(m):
            if i != j and ((s.group and s.group == specs[j].group) or names[j] in s.ignore
                           or names[i] in specs[j].ignore):
                ok[i, j] = ok[j, i] = False
    return ok
