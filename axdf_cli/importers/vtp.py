"""VTK PolyData XML (``.vtp``, ASCII) bone meshes → triangles (the importer writes them as PLY).

Reads the ``<Points>`` of every ``<Piece>`` and triangulates ``<Polys>`` (fans) and
``<Strips>`` (alternating winding, as VTK does); ``<Verts>``/``<Lines>`` carry no surface and
are skipped. Only ``format="ascii"`` arrays are read (OpenSim's shipped geometry); binary or
appended data is refused with an :class:`InputError` naming the line.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from axdf_cli import tolerances as tol
from axdf_cli.errors import InputError
from axdf_cli.importers.xmltree import Node, parse_xml


def _array(node: Node, dtype, what: str) -> np.ndarray:
    fmt = node.attrib.get("format", "ascii")
    if fmt != "ascii":
        raise InputError(node.mark, f"{what} is stored as format={fmt!r}", "ASCII VTP (format=\"ascii\")")
    try:
        return np.array(node.text.split(), dtype=np.float64).astype(dtype)
    except ValueError:
        raise InputError(node.mark, f"malformed number in {what}", "numbers separated by spaces") from None


def _cells(cell_node: Node | None, piece: Node, what: str):
    if cell_node is None:
        return []
    arrays = {a.attrib.get("Name"): a for a in cell_node.findall("DataArray")}
    if "connectivity" not in arrays or "offsets" not in arrays:
        raise InputError(cell_node.mark, f"<{what}> lacks connectivity or offsets", "both DataArrays")
    conn = _array(arrays["connectivity"], np.int64, f"{what} connectivity")
    offs = _array(arrays["offsets"], np.int64, f"{what} offsets")
    starts = np.concatenate([[0], offs[:-1]]) if len(offs) else offs
    if len(offs) and (offs[-1] != len(conn) or np.any(np.diff(offs) < 0)):
        raise InputError(arrays["offsets"].mark, f"{what} offsets do not match connectivity ({len(conn)} indices)",
                         "increasing offsets ending at the connectivity length")
    return [conn[s:e] for s, e in zip(starts, offs)]


def read_vtp(path: Path | str) -> tuple[np.ndarray, np.ndarray]:
    """Vertices (V, 3) float64 and triangles (T, 3) int64 of a VTP file (all pieces merged)."""
    root = parse_xml(path)
    if root.tag != "VTKFile" or root.attrib.get("type") != "PolyData":
        raise InputError(root.mark, f"<{root.tag} type={root.attrib.get('type')!r}>", "a VTK PolyData XML file")
    pd = root.find("PolyData")
    if pd is None:
        raise InputError(root.mark, "no <PolyData>", "a VTK PolyData XML file")
    verts, tris = [], []
    base = 0
    for piece in pd.findall("Piece"):
        pts_node = piece.path("Points", "DataArray")
        if pts_node is None:
            raise InputError(piece.mark, "piece has no <Points>", "<Points><DataArray ...>")
        pts = _array(pts_node, np.float64, "Points")
        if pts.size % 3:
            raise InputError(pts_node.mark, f"Points has {pts.size} numbers", "a multiple of 3")
        pts = pts.reshape(-1, 3)
        bad = ~np.isfinite(pts) | (np.abs(pts) > tol.MAX_ABS_NUMBER)
        if bad.any():
            i, k = (int(x) for x in np.argwhere(bad)[0])
            raise InputError(pts_node.mark, f"point {i} of Points has {'xyz'[k]} = {float(pts[i, k])!r}",
                             f"finite coordinates within ±{tol.MAX_ABS_NUMBER:g}")
        local = []
        for cell in _cells(piece.find("Polys"), piece, "Polys"):
            for k in range(1, len(cell) - 1):
                local.append((cell[0], cell[k], cell[k + 1]))
        for cell in _cells(piece.find("Strips"), piece, "Strips"):
            for k in range(len(cell) - 2):
                a, b, c = cell[k], cell[k + 1], cell[k + 2]
                local.append((a, b, c) if k % 2 == 0 else (b, a, c))
        t = np.asarray(local, dtype=np.int64).reshape(-1, 3)
        if len(t) and (t.min() < 0 or t.max() >= len(pts)):
            raise InputError(piece.mark, f"a cell refers to point {int(t.max())} of {len(pts)}",
                             "indices below the piece's point count")
        verts.append(pts)
        tris.append(t + base)
        base += len(pts)
    v = np.concatenate(verts) if verts else np.zeros((0, 3))
    t = np.concatenate(tris) if tris else np.zeros((0, 3), dtype=np.int64)
    return v, t

