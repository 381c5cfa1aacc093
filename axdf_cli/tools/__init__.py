"""Tools that rewrite axdf files: muscles moved onto another skeleton (:mod:`~axdf_cli.tools.transfer`),
a motion fitted onto a skeleton (:mod:`~axdf_cli.tools.retarget`), a library's rest shapes packed
(:mod:`~axdf_cli.tools.pack`). They read and write axdf files only; readers of other tools'
formats live in :mod:`axdf_cli.importers`, below this room.
"""
