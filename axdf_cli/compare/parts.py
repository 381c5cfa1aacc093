"""Which parts (muscles, bones, the skin) a comparison's differences belong to, by name.

A run's files say whose they are: a mesh file lies in ``meshes/<part>/``; a row of
``stats.csv`` or ``bones.csv`` names its muscle or bone; a frame's pixels carry the id of the
part they show in the frame's OpenEXR ``id`` channel, which ``camera.json``'s ``ids`` table
names. :func:`pixel_parts` counts an image's failing pixels by the parts at them (golden's
and actual's; for a pixel that shows the background on both sides, the parts of its 8
neighbours: a silhouette pixel whose colour blends a part into the background is that part's), and :func:`differing_parts` gathers every failing file's parts
into one table for the report ("biceps_brachii: 3 mesh files, stats.csv 3 rows, 1 image").
"""
from __future__ import annotations

import json
from pathlib import Path, PurePosixPath

import numpy as np

#: the name pixels get when no part is at or next to them
BACKGROUND = "(background)"
#: a part's folder in a run: meshes/<part>/<part>_<frame>.<ext>
MESH_FOLDER = "meshes"


def _id_names(root: Path) -> dict[int, str]:
    """``camera.json``'s ``ids``: id -> part name (the background's id left out); {} when the
    file is missing or not a run's."""
    try:
        doc = json.loads((root / "camera.json").read_bytes())
        ids = doc["ids"]
        return {int(k): str(v["name"]) for k, v in ids.items() if isinstance(v, dict) and v.get("name")}
    except (OSError, ValueError, KeyError, TypeError, AttributeError):
        return {}


def _ids(root: Path, rel: str) -> np.ndarray | None:
    """(H, W) int64 the ``id`` channel of the frame ``rel`` names (``frames/0007.png`` ->
    ``frames/0007.exr``), or None when there is none to read."""
    from axdf_cli.compare.images import read_exr
    from axdf_cli.compare.result import Unreadable

    p = root / PurePosixPath(rel).with_suffix(".exr")
    if not p.is_file() or p.is_symlink():
        return None
    try:
        ch = read_exr(p.read_bytes())
    except (Unreadable, OSError):
        return None
    return ch["id"].astype(np.int64) if "id" in ch else None


def _near(ids: np.ndarray) -> list[np.ndarray]:
    """The id image shifted by each of the 9 offsets of a 3x3 neighbourhood (edges repeated)."""
    pad = np.pad(ids, 1, mode="edge")
    h, w = ids.shape
    return [pad[1 + dy:1 + dy + h, 1 + dx:1 + dx + w] for dy in (-1, 0, 1) for dx in (-1, 0, 1)]


def pixel_parts(failing: np.ndarray, rel: str, roots: tuple[Path | None, Path | None]) -> dict[str, int] | None:
    """Failing pixels (``failing`` (H, W) bool) of the frame image ``rel`` counted by the parts
    at them on either side (``roots``: the actual and golden run folders), or, where both
    sides show the background, next to them; a pixel of two parts counts for both, one near
    none for :data:`BACKGROUND`. None when the frame
    has no id image of the same size on both sides, or no names."""
    if roots[0] is None or roots[1] is None or not failing.any():
        return None
    names = _id_names(roots[1]) or _id_names(roots[0])
    sides = [_ids(r, rel) for r in roots]
    if not names or any(s is None or s.shape != failing.shape for s in sides):
        return None
    ys, xs = np.nonzero(failing)
    at = np.stack([s[ys, xs] for s in sides], axis=1)  # (P, 2) the ids at each failing pixel, both sides
    near = np.stack([n[ys, xs] for s in sides for n in _near(s)], axis=1)  # (P, 18) and around it
    ids = np.where((at != 0).any(axis=1, keepdims=True), np.pad(at, ((0, 0), (0, 16))), near)
    out: dict[str, int] = {}
    known = np.zeros(len(ys), bool)
    for i, name in sorted(names.items()):
        hit = (ids == i).any(axis=1)
        if hit.any():
            out[name] = out.get(name, 0) + int(hit.sum())
            known |= hit
    if (~known).any():
        out[BACKGROUND] = int((~known).sum())
    return out


def mesh_part(rel: str) -> str | None:
    """The part a run's mesh file belongs to (``meshes/<part>/...``), or None."""
    parts = PurePosixPath(rel).parts
    return parts[1] if len(parts) >= 3 and parts[0] == MESH_FOLDER else None


def differing_parts(files) -> tuple[dict[str, list[str]], dict[str, int]]:
    """(part name -> what of it differs, part name -> failing pixels it only shows) over a
    comparison's files (:class:`~axdf_cli.compare.result.FileResult`): a part differs by its
    failing mesh files, the failing rows of a table that name it, and the failing pixels of
    images that show it; but a part whose mesh files all pass is not one that differs: the
    failing pixels on it (a silhouette pixel it shares with a part that grew) are listed
    apart, in the second table. Names sorted."""
    meshes: dict[str, int] = {}
    same: set[str] = set()
    rows: dict[str, list[str]] = {}
    images: dict[str, list[tuple[str, int]]] = {}
    for f in files:
        part = mesh_part(f.path)
        if part is not None and not f.failed:
            same.add(part)
        if not f.failed:
            continue
        if part is not None:
            meshes[part] = meshes.get(part, 0) + 1
        for name, n in (f.metrics.get("differing_names") or {}).items():
            rows.setdefault(name, []).append(f"{f.path} {n} row(s)")
        for name, n in (f.metrics.get("failing_pixels_by_part") or {}).items():
            images.setdefault(name, []).append((f.path, n))
    out: dict[str, list[str]] = {}
    shown: dict[str, int] = {}
    for name in sorted(set(meshes) | set(rows) | set(images)):
        ims = images.get(name, [])
        if name not in meshes and name not in rows and name in same:
            shown[name] = sum(n for _, n in ims)
            continue
        what = [f"{meshes[name]} mesh file(s)"] if name in meshes else []
        what += rows.get(name, [])
        if ims:
            what.append(f"{sum(n for _, n in ims)} failing pixel(s) in {len(ims)} image(s)")
        out[name] = what
    return out, shown
