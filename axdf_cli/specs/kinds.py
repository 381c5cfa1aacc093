"""Telling a YAML file's kind (skeleton, pose, muscle, job, transfer or retarget map) from its top-level keys."""
from __future__ import annotations

from axdf_cli.errors import InputError, Mark
from axdf_cli.fileio.yamlio import YMap, did_you_mean, mark_of


#: The keys that tell a file's kind (see :func:`detect_kind`).
KIND_KEYS = ("skeleton", "bones", "pose", "keys", "muscle", "muscles", "transfer", "retarget")
KINDS_ALLOWED = ("a skeleton (skeleton:, bones:), pose (pose:, keys:), muscle (muscle:), job (muscles:, pose:), "
                 "transfer map (transfer:, bones:) or retarget map (retarget:, joints:)")


def detect_kind(doc) -> str | None:
    if not isinstance(doc, dict):
        return None
    if "transfer" in doc:
        return "transfer"
    if "retarget" in doc:
        return "retarget"
    if "skeleton" in doc and "bones" in doc:
        return "skeleton"
    if "pose" in doc and "keys" in doc:
        return "pose"
    if "muscle" in doc or ("muscles" in doc and "pose" not in doc):
        return "muscle"
    if "muscles" in doc and "pose" in doc:
        return "job"
    return None


def kind_error(doc, top: Mark, problem: str = "unknown kind of file", allowed: str = KINDS_ALLOWED,
               kind_keys=KIND_KEYS) -> InputError:
    """The error for a file whose kind cannot be told: a top-level key close to a kind key
    (``muscel:``) is named, with its position and the key it probably means."""
    if isinstance(doc, dict):
        for key in doc:
            if key in KIND_KEYS:
                continue
            hint = did_you_mean(key, kind_keys)
            if hint:
                where = doc.key_mark(key) if isinstance(doc, YMap) else top
                return InputError(where, f"{problem}: unknown key {key!r}", f"{hint}{allowed}")
    return InputError(mark_of(doc, top), problem, allowed)
