"""Shared geometry of closed triangle meshes, each rule written once: inside and outside by
the generalized winding number (:mod:`.winding`), points pushed out of meshes, boundary loops
capped (:mod:`.mesh`), and a skeleton's bone meshes read and placed at rest (:mod:`.bones`).

A room right above :mod:`axdf_cli.model`: it imports only errors, tolerances, fileio, formats
and model; the pipeline, the tools, the data set and the bench import it, model/ never does.
Arrays are float64 vertices (V, 3), int64 faces (T, 3) and float64 points (N, 3) unless a
docstring says otherwise.
"""
