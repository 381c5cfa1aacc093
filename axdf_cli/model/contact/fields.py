"""The bones' signed distance fields: one per bone, sampled once per run on a bone-local grid
(libigl's ``signed_distance`` with the fast winding number sign of Barill et al. 2018, so a
bone mesh that is not closed still has an inside: the points whose generalized winding number
exceeds 1/2), read trilinearly between grid points (:func:`query.bone_query`)."""
from __future__ import annotations

import functools
import hashlib
from dataclasses import dataclass

import numpy as np

from axdf_cli import tolerances as tol
from axdf_cli.errors import EnvironmentProblem
from axdf_cli.model.contact.params import Fields


@dataclass(frozen=True)
class BoneField:
    """A bone's signed distance field on a regular bone-local grid (negative inside).

    origin (3,) the grid's first point, h the spacing (m), values (nx, ny, nz) float64."""

    bone: int
    origin: np.ndarray
    h: float
    values: np.ndarray


def bone_field(bone: int, vertices: np.ndarray, faces: np.ndarray, clip: np.ndarray | None = None,
               h: float = tol.CONTACT_SDF_STEP, pad: float = tol.CONTACT_SDF_PAD, cache=None) -> BoneField | None:
    """The signed distance field of a bone mesh (bone-local vertices (V, 3), faces (T, 3)) on a
    grid of spacing ``h`` over its bounds grown by ``pad``, cut to the box ``clip`` (2, 3)
    where muscles can reach (None where that leaves nothing). ``cache(key, compute)`` →
    (origin, values), where given, looks the field up by a digest of the mesh and the grid
    (:func:`axdf_cli.fileio.fieldcache.cached`); without it the field is computed."""
    v = np.ascontiguousarray(vertices, dtype=np.float64)
    f = np.ascontiguousarray(faces, dtype=np.int64)
    lo = v.min(axis=0) - pad
    hi = v.max(axis=0) + pad
    if clip is not None:
        # the box in whole tol.CONTACT_CLIP_STEP: small edits to the muscles keep the same field (cache)
        q = tol.CONTACT_CLIP_STEP
        lo = np.maximum(lo, np.floor(clip[0] / q) * q)
        hi = np.minimum(hi, np.ceil(clip[1] / q) * q)
        if np.any(hi <= lo):
            return None
    lo = np.floor(lo / h) * h  # on a grid fixed in the bone: the same field for any box
    box = np.concatenate([lo, hi])
    compute = functools.partial(compute_field, v, f, h, box)
    if cache is None:
        origin, values = compute()
    else:
        key = hashlib.sha256(v.tobytes() + f.tobytes() + np.array([h, *box]).tobytes()).hexdigest()
        origin, values = cache(key, compute)
    return BoneField(bone, origin, h, values)


def compute_field(v: np.ndarray, f: np.ndarray, h: float, box: np.ndarray) -> tuple:
    """(origin (3,), values (nx, ny, nz)): the signed distance of mesh (v, f) at the grid of
    spacing h from box[:3] to past box[3:]."""
    try:
        import igl
    except ImportError as e:
        raise EnvironmentProblem(f"contact needs libigl for the bones' distance fields ({e})",
                                 "pip install libigl (make setup installs it), or run with --no-contact") from None
    lo = box[:3]
    n = np.ceil((box[3:] - lo) / h).astype(np.int64) + 1
    axes = [lo[i] + h * np.arange(n[i]) for i in range(3)]
    pts = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
    sd = igl.signed_distance(pts, v, f, sign_type=igl.SIGNED_DISTANCE_TYPE_FAST_WINDING_NUMBER)[0]
    return lo, np.ascontiguousarray(np.asarray(sd, dtype=np.float64).reshape(tuple(n)))


@dataclass(frozen=True)
class BoneFields:
    """Every bone field of a skeleton, packed for the compiled kernels."""

    bones: np.ndarray  # (K,) bone index of each field
    origin: np.ndarray  # (K, 3)
    h: np.ndarray  # (K,)
    dims: np.ndarray  # (K, 3) int64
    offset: np.ndarray  # (K + 1,) start of each field in ``values``
    values: np.ndarray  # (sum of grid sizes,) float64

    @staticmethod
    def pack(fields: list[BoneField]) -> "BoneFields":
        dims = np.array([f.values.shape for f in fields], dtype=np.int64).reshape(-1, 3)
        sizes = np.prod(dims, axis=1) if len(fields) else np.zeros(0, np.int64)
        return BoneFields(np.array([f.bone for f in fields], dtype=np.int64),
                          np.array([f.origin for f in fields], dtype=np.float64).reshape(-1, 3),
                          np.array([f.h for f in fields], dtype=np.float64), dims,
                          np.concatenate([[0], np.cumsum(sizes)]).astype(np.int64),
                          np.concatenate([f.values.ravel() for f in fields]) if fields else np.zeros(0))

    def posed(self, inv: np.ndarray):
        """The fields as the kernels take them (:class:`params.Fields`), with the world to
        bone-local transforms ``inv`` (B, 4, 4)."""
        return Fields(inv, self.bones, self.origin, self.h, self.dims, self.offset, self.values)
