"""axdf: AxDf axial-deformation muscles (Zuo, Li, Wang) as a headless command-line tool.

Importing the package changes nothing in the process; the command line's entry sets up its
threads and kernel cache (:func:`axdf_cli.runtime.configure`)."""

__version__ = "0.1.0"
