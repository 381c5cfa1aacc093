"""Muscle files, written and read as a set: one muscle's YAML document with every field
(:func:`muscle_doc`, docs/FORMATS.md "Muscle"), a file's (:func:`file_doc`: one muscle or a
group), and the muscle files of a command that writes one file per file read into one folder
(:func:`load_muscle_files`: transfer, pack). Used by axdf fit, pack and transfer.
"""
from __future__ import annotations

from pathlib import Path

from axdf_cli.errors import InputError, Mark
from axdf_cli.fileio.yamlio import load_yaml
from axdf_cli.importers import emit
from axdf_cli.model.muscle import MuscleSpec
from axdf_cli.specs import load_muscle_file


def _color(c: tuple) -> str | list:
    """``#rrggbb`` when the colour is exactly one (as read from one), else the numbers."""
    b = [round(x * 255) for x in c]
    if all(abs(x * 255 - y) < 1e-9 for x, y in zip(c, b)):
        return "#{:02x}{:02x}{:02x}".format(*b)
    return [float(x) for x in c]


def muscle_doc(spec: MuscleSpec) -> dict:
    """One muscle's YAML document (docs/FORMATS.md, "Muscle"): every field written out."""
    d = {"muscle": spec.name, "color": _color(spec.color), "strength": spec.strength, "tension": spec.tension,
         "volume": spec.volume}
    if spec.axis:  # (with a path too: the belly's shape, the path its line of action)
        d["axis"] = [{"bone": p.bone, "at": list(p.at)} for p in spec.axis]
    if spec.path is not None:
        d["path"] = [emit.point_doc(p) for p in spec.path.points]
        if spec.path.wraps:
            d["wrap"] = [emit.wrap_doc(w) for w in spec.path.wraps]
        if spec.path.control_points:
            d["axis_points"] = spec.path.control_points
    if all(s.radii is not None or s.outline is not None for s in spec.sections):  # else the default sections
        d["sections"] = [{"t": s.t, "outline": [list(p) for p in s.outline]} if s.outline is not None
                         else {"t": s.t, "radii": list(s.radii), "angle": s.angle} for s in spec.sections]
    d["tendons"] = list(spec.tendons)
    d["twist"] = spec.twist
    d["resolution"] = list(spec.resolution)
    if spec.weights is not None:
        d["weights"] = list(spec.weights)
    if spec.jiggle is not None:
        d["jiggle"] = emit.jiggle_doc(spec.jiggle)
    c = spec.contact
    doc = {k: v for k, v in (("group", c.group), ("ignore", list(c.ignore)), ("yield", c.yield_)) if v not in ("", [], None)}
    if doc:
        d["contact"] = doc
    return d


def file_doc(specs: list[MuscleSpec]) -> dict:
    """A muscle file: one muscle, or a ``group`` with its ``muscles`` (heads)."""
    if len(specs) == 1 and not specs[0].group:
        return muscle_doc(specs[0])
    return {"group": specs[0].group, "muscles": [muscle_doc(s) for s in specs]}


def load_muscle_files(muscle_files: list[Path], what: str) -> list[tuple[Path, list[MuscleSpec]]]:
    """Every file's muscles, in order, for a command that writes one file per muscle file into
    one folder (transfer, pack): the files' names distinct, the muscles' names unique
    (``what``: "transferred", "packed"). Reads everything before anything is made."""
    out: list[tuple[Path, list[MuscleSpec]]] = []
    names: dict[str, Path] = {}
    defined: dict[str, Path] = {}
    for path in muscle_files:
        if path.name in names:
            raise InputError(Mark(str(path)), f"two muscle files named {path.name} ({names[path.name]} and {path})",
                             "muscle files with distinct names (they share the output folder)")
        names[path.name] = path
        specs = load_muscle_file(path)
        for spec in specs:
            if spec.name in defined:
                raise InputError(muscle_mark(path, spec.name), f"muscle {spec.name!r} is also defined in "
                                 f"{defined[spec.name]}", f"muscle names are unique among the {what} files")
            defined[spec.name] = path
        out.append((path, specs))
    return out


def muscle_mark(path: Path, name: str) -> Mark:
    """Where muscle ``name`` is named in its file (read again: only for a message)."""
    doc = load_yaml(path)
    if isinstance(doc, dict):
        if doc.get("muscle") == name and hasattr(doc, "value_mark"):
            return doc.value_mark("muscle")
        heads = doc.get("muscles")
        if isinstance(heads, list):
            for item in heads:
                if isinstance(item, dict) and item.get("muscle") == name and hasattr(item, "value_mark"):
                    return item.value_mark("muscle")
    return Mark(str(path), 1, 1)
