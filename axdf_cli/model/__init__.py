"""The model: skeleton and forward kinematics, pose sampling, the AxDf muscle (binding and
deformation), muscle paths and wrap surfaces, B-spline and rotation-minimizing-frame maths,
and the compiled kernels. Pure functions of arrays and small frozen specs; no files, no
output. Imports nothing of axdf but :mod:`axdf_cli.errors` and :mod:`axdf_cli.tolerances`."""
