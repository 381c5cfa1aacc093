"""Mesh writers, one module per format, registered in one table.

Each writer is built once per muscle with its fixed faces ``(T, 3) int32`` and encodes one
frame ``positions (V, 3), normals (V, 3)`` to bytes. ``--format`` choices come from
:data:`WRITERS`.
"""
from __future__ import annotations

from axdf_cli.formats.obj import ObjWriter
from axdf_cli.formats.ply import PlyWriter

WRITERS = {PlyWriter.extension: PlyWriter, ObjWriter.extension: ObjWriter}

__all__ = ["WRITERS", "PlyWriter", "ObjWriter"]
