"""The input files, one module per kind: YAML → small frozen specs, every check reported as
``FILE:LINE:COL: what is wrong; what is allowed`` (docs/FORMATS.md).

- :mod:`.skeleton`: skeletons (bones, DOFs, coordinate functions);
- :mod:`.muscle`: muscles (axis or path, sections, wrap surfaces);
- :mod:`.pose`: poses (keys, activation) on a skeleton;
- :mod:`.job`: jobs (muscles, pose, out, format, frames, render);
- :mod:`.render`: render settings (a job's ``render:`` and the render flags);
- :mod:`.refs`: where referenced files may lie (:class:`RefPolicy`), muscle paths expanded;
- :mod:`.kinds`: telling a file's kind from its keys.

Paths written inside YAML files are resolved relative to the file that holds them and
checked against a :class:`RefPolicy`, passed down explicitly (no global state). The names
below are the package's public face.
"""
from axdf_cli.specs.job import JOB_KEYS, Job, load_job
from axdf_cli.specs.kinds import KIND_KEYS, KINDS_ALLOWED, detect_kind, kind_error
from axdf_cli.specs.muscle import (MUSCLE_KEYS, WRAP_SIZE_KEYS, default_color, load_muscle_file, muscles_from_document,
                                   parse_color, parse_muscle_path, parse_muscle_text)
from axdf_cli.specs.pose import INTERPOLATIONS, MOTION_IMPORTS, POSE_KEYS, Pose, load_pose, parse_pose_text
from axdf_cli.specs.refs import LIBRARY_ROOTS, RefPolicy, expand_muscle_paths
from axdf_cli.specs.skeleton import (DOF_TYPES, FUNCTION_KINDS, load_skeleton, parse_function, parse_skeleton_text,
                                     skeleton_from_document)

__all__ = ["DOF_TYPES", "FUNCTION_KINDS", "INTERPOLATIONS", "JOB_KEYS", "KINDS_ALLOWED", "KIND_KEYS", "LIBRARY_ROOTS",
           "MOTION_IMPORTS", "MUSCLE_KEYS", "POSE_KEYS", "WRAP_SIZE_KEYS", "Job", "Pose", "RefPolicy", "default_color",
           "detect_kind", "expand_muscle_paths", "kind_error", "load_job", "load_muscle_file", "load_pose",
           "load_skeleton", "muscles_from_document", "parse_color", "parse_function", "parse_muscle_path",
           "parse_muscle_text", "parse_pose_text", "parse_skeleton_text", "skeleton_from_document"]
