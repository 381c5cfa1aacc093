"""Importers: other tools' files → axdf skeletons, muscles and poses, through one neutral model.

- :mod:`axdf_cli.importers.model`: the neutral model every reader fills (bones, coordinates,
  meshes, muscles, motion) and the rules a format's import follows.
- :mod:`axdf_cli.importers.emit`: the one emitter: the model → skeleton, muscles, pose,
  report and IMPORT.md (deterministic YAML text), with the belly law and the axis-points rule.
- :mod:`axdf_cli.importers.result`: what an import returns, what its files may hold, IMPORT.md's text.
- :mod:`axdf_cli.importers.osim`, :mod:`~axdf_cli.importers.osim_model`: OpenSim 4 ``.osim``
  models; :mod:`~axdf_cli.importers.osim_import` reads them (+ motion, controls) into the model.
- :mod:`axdf_cli.importers.storage`: OpenSim ``.mot`` / ``.sto`` tables.
- :mod:`axdf_cli.importers.vtp`: VTK PolyData XML (ASCII) bone meshes → triangles.
- :mod:`axdf_cli.importers.mjcf`, :mod:`~axdf_cli.importers.mjcf_import`: MuJoCo MJCF models.
- :mod:`axdf_cli.importers.qpos`: MuJoCo ``qpos`` motions (``import mjcf --motion``, data sets).
- :mod:`axdf_cli.importers.bvh`: Biovision motion capture; :mod:`~axdf_cli.importers.mocap`:
  joint positions of a take (``retarget``).
- :mod:`axdf_cli.importers.xmltree`: XML with a line and column on every element.
"""
