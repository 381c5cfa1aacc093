"""Importers: other tools' files → axdf skeletons, muscles and poses.

- :mod:`axdf_cli.importers.xmltree`: XML with a line and column on every element.
- :mod:`axdf_cli.importers.osim`: OpenSim 4 ``.osim`` models → :class:`~axdf_cli.importers.osim.Model`.
- :mod:`axdf_cli.importers.storage`: OpenSim ``.mot`` / ``.sto`` tables.
- :mod:`axdf_cli.importers.vtp`: VTK PolyData XML (ASCII) bone meshes → triangles, binary PLY.
- :mod:`axdf_cli.importers.emit`: the model → axdf YAML documents (deterministic text), the belly
  law and the one axis-points rule of both model importers.
- :mod:`axdf_cli.importers.result`: what a model importer returns, and what its files may hold.
- :mod:`axdf_cli.importers.mjcf`, :mod:`~axdf_cli.importers.mjcf_import`: MuJoCo MJCF models.
- :mod:`axdf_cli.importers.qpos`: MuJoCo ``qpos`` motions (``import mjcf --motion``, data sets).
"""
