"""The amodal masks of a sequence as a COCO annotation file (``OUT/<seq>/amodal.json``).

COCO's instance-segmentation layout (Lin et al. 2014, cocodataset.org "Data format"), as the
amodal data sets COCOA and KINS use it: ``images`` (one per view and frame: ``file_name``
the PNG relative to the sequence folder, ``width``, ``height``, and our ``frame`` and
``view``), ``categories`` (one per muscle: ``id`` = its id in the EXR ``id`` pass, ``name``),
``annotations`` (one per muscle that the view sees any part of): ``segmentation`` the
muscle's **amodal** mask (its full extent, occluders ignored) as uncompressed RLE
``{"size": [H, W], "counts": [...]}`` (column-major runs, the first one of 0s, as
``pycocotools.mask.frPyObjects`` reads it), ``area`` and ``bbox`` ``[x, y, w, h]`` (pixels)
of that mask, ``iscrowd`` 0, and ``visible_area``: the pixels of the muscle that the ``id``
pass shows (``visible_area / area`` is how much of it is not hidden).
"""
from __future__ import annotations

import numpy as np


def rle_counts(mask: np.ndarray) -> list[int]:
    """COCO's uncompressed RLE of a (H, W) bool mask: run lengths down the columns (Fortran
    order), starting with a run of 0s (of length 0 when the first pixel is set)."""
    flat = np.asarray(mask, dtype=np.int8).T.ravel()  # column-major
    edges = np.flatnonzero(np.diff(flat)) + 1
    counts = np.diff(np.concatenate([[0], edges, [flat.size]])).tolist()
    return ([0] + counts) if flat.size and flat[0] else counts


def rle_decode(counts: list[int], size: tuple[int, int]) -> np.ndarray:
    """(H, W) bool mask of uncompressed RLE ``counts`` (the inverse of :func:`rle_counts`)."""
    H, W = size
    values = np.arange(len(counts)) % 2 == 1
    return np.repeat(values, counts).reshape(W, H).T


def annotations(masks: np.ndarray, ids: np.ndarray, image_id: int, first_id: int) -> list[dict]:
    """The annotations of one image: ``masks`` (M, H, W) bool amodal masks of muscles 1..M,
    ``ids`` (H, W) the ``id`` pass; ids of the annotations count from ``first_id``."""
    M, H, W = masks.shape
    area = masks.sum(axis=(1, 2))
    visible = np.bincount(ids.ravel(), minlength=M + 1)[1:M + 1]
    out = []
    for m in np.flatnonzero(area):
        rows = np.flatnonzero(masks[m].any(axis=1))
        cols = np.flatnonzero(masks[m].any(axis=0))
        out.append({"id": first_id + len(out), "image_id": image_id, "category_id": int(m) + 1,
                    "segmentation": {"size": [H, W], "counts": rle_counts(masks[m])},
                    "area": int(area[m]), "bbox": [int(cols[0]), int(rows[0]), int(cols[-1] - cols[0] + 1),
                                                   int(rows[-1] - rows[0] + 1)],
                    "iscrowd": 0, "visible_area": int(visible[m])})
    return out


def coco_dict(muscles: list[str], images: list[dict], anns: list[dict]) -> dict:
    """The whole file: ``images`` and ``anns`` as collected per view and frame."""
    return {"info": {"description": "axdf amodal muscle masks (full extent, occluders ignored)",
                     "segmentation": "uncompressed RLE, column-major, as pycocotools.mask.frPyObjects reads it"},
            "categories": [{"id": i + 1, "name": n, "supercategory": "muscle"} for i, n in enumerate(muscles)],
            "images": images, "annotations": anns}
