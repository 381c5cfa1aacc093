"""An importer writes only what ``axdf validate`` accepts: every YAML file it is about to
write is read back with the file spec's own checks (skeletons, muscles, poses), before the
first byte, from the bytes in memory.

Importers check their inputs where they can name the input's line and column (a BVH's
``Frame Time``, a joint's name); this is the backstop that makes the limits agree whatever
the importer: a file the loaders would refuse is never written (exit 2, naming the file
that would have been written and why).
"""
from __future__ import annotations

import re

from axdf_cli import tolerances as tol
from axdf_cli.errors import InputError
from axdf_cli.fileio.yamlio import parse_yaml
from axdf_cli.specs import RefPolicy, detect_kind, muscles_from_document, skeleton_from_document
from axdf_cli.specs.pose import pose_from_document

ALLOWED = "the importer writes only files axdf validate accepts; this input is beyond what they may hold"


def check_documents(outputs, source=None, progress=None) -> None:
    """Read every ``.yaml`` of ``outputs`` (an :class:`~axdf_cli.fileio.outputs.OutputSet`)
    back as axdf would: skeletons first (a pose may name one that is not on disk yet), then
    muscles and poses, one file at a time (memory: the largest file's document). ``source``:
    the input file, for the message; ``progress(n)``: called per file checked."""
    policy = RefPolicy(allow_outside=True)
    yamls = [o for o in outputs if o.path.suffix.lower() in (".yaml", ".yml")]
    for o in yamls:
        if len(o.data) > tol.YAML_MAX_BYTES:
            raise InputError(source, f"{o.what} {o.path.name} would be {len(o.data)} bytes",
                             f"axdf reads YAML files up to {tol.YAML_MAX_BYTES} bytes; {ALLOWED}")
    skeletons = {}
    for o in sorted(yamls, key=lambda o: not _SKELETON.search(o.data)):  # skeletons first (a cheap look)
        doc = _read(o, source, lambda text, shown: parse_yaml(text, shown))
        kind = detect_kind(doc)
        if kind == "skeleton":
            skeletons[o.path] = _read(o, source, lambda *_: skeleton_from_document(doc, o.path, policy))
        elif kind == "muscle":
            _read(o, source, lambda *_: muscles_from_document(doc, o.path))
        elif kind == "pose":
            _read(o, source, lambda *_: pose_from_document(doc, o.path, policy, skeletons))
        del doc
        if progress:
            progress(1)


_SKELETON = re.compile(rb"^skeleton:.*^bones:", re.M | re.S)


def _read(o, source, fn):
    try:
        return fn(o.data.decode("utf-8"), str(o.path))
    except InputError as e:
        raise InputError(source, f"{o.what} {o.path.name} would not pass axdf validate ({e})", ALLOWED) from None
