"""Importers: other tools' files → axdf skeletons, muscles and poses.

- :mod:`axdf_cli.importers.xmltree`: XML with a line and column on every element.
- :mod:`axdf_cli.importers.osim`: OpenSim 4 ``.osim`` models → :class:`~axdf_cli.importers.osim.Model`.
- :mod:`axdf_cli.importers.storage`: OpenSim ``.mot`` / ``.sto`` tables.
- :mod:`axdf_cli.importers.vtp`: VTK PolyData XML (ASCII) bone meshes → triangles, binary PLY.
- :mod:`axdf_cli.importers.emit`: the model → axdf YAML documents (deterministic text).
"""
