"""axdf: AxDf axial-deformation muscles (Zuo, Li, Wang) as a headless command-line tool."""

__version__ = "0.1.0"
