"""What every import returns (:class:`ImportResult`), the small rules for what goes into the
files it writes (references between output files are relative, no absolute path or directory
of an input appears, names are axdf names, whole numbers are written as integers), and the
text of IMPORT.md (:func:`import_markdown`).

Imports build their files in memory; the CLI hands them to
``axdf_cli.cli.importer.write_imported``, which checks and writes them (the output rule).
"""
from __future__ import annotations

import math
import os
import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

#: Side suffixes: a muscle and its mirror image share their colour and their belly note.
SIDE_SUFFIX = re.compile(r"_[lr]\Z")


@dataclass
class ImportResult:
    files: dict[str, bytes]  # output path (as given by the layout) -> bytes
    report: dict
    warnings: list[str] = field(default_factory=list)  # for the user (stderr; BVH: the unit guess, stdout)
    inputs: list[Path] = field(default_factory=list)  # the model, its includes, the motion: listed in the manifest
    assets: list[Path] = field(default_factory=list)  # other files read (bone meshes): never an output either
    layout: dict = field(default_factory=dict)  # "muscles", "skeleton", "pose": where the import put them (or None)


def relative_ref(target: Path | str, start_dir: Path | str) -> str:
    """``target`` as a file written in ``start_dir`` refers to it: relative, '/'-separated
    (real paths: a reference that survives the import's own folders being links)."""
    # (os.path.realpath never raises; Path.resolve raises RuntimeError on a link loop in 3.11)
    return Path(os.path.relpath(os.path.realpath(target), os.path.realpath(start_dir))).as_posix()


def strip_dirs(text: str, inputs: list[Path]) -> str:
    """No absolute paths in output files: input paths in ``text`` become their file names."""
    for p in inputs:
        text = text.replace(str(p), p.name)
    return text


def safe_name(s: str) -> str:
    """``s`` as an axdf name: runs of other characters than ``[A-Za-z0-9_.-]`` become ``_``."""
    s = re.sub(r"[^A-Za-z0-9_.-]+", "_", s).strip("_")
    return s if s and s not in (".", "..") else "model"


def yaml_number(x: float) -> float | int:
    """A number as YAML should show it: a whole number as an integer (``fps: 60``)."""
    x = float(x)
    return int(x) if x.is_integer() and abs(x) < 2**53 else x


# ----------------------------------------------------------------------------- IMPORT.md


def axis_markdown(r: dict, poses: str) -> list[str]:
    """IMPORT.md's list of the muscles whose axis control points were raised (the report rows'
    ``axis_points_raised``: emit.axis_points_for); ``poses`` names the poses measured."""
    from axdf_cli import tolerances as tol

    raised = [m for m in r["muscles"] if "axis_points_raised" in m]
    if not raised:
        return []
    return [f"Axis control points raised where the default count leaves the axis more than "
            f"{tol.AXIS_SHORTFALL_MAX:.1%} short of the wrapped path somewhere over {poses} (a bend the smooth "
            "axis cuts):",
            ""] + [f"- {m['muscle']}: {a['from']} → {a['to']} (shortfall {a['shortfall_at_default']:.2%} → "
                   f"{a['shortfall']:.2%})" for m in raised for a in [m["axis_points_raised"]]] + [""]


#: Bellies whose slenderness (axdf_cli/model/measure.py) is below this are listed in IMPORT.md, each
#: with its numbers and why it is short or squat.
SHORT_BELLY = 2.0
#: Squat: the issue's aim is none below 1.2 and at most 5% of a library below 1.5.
SQUAT_BELLY = 1.5

#: Why a muscle of the OpenSim leg and arm models has a short or squat belly, by name without
#: its side suffix (a prefix matches a family). Anatomy from the models' sources (Delp 1990,
#: Holzbaur 2005) and standard texts; the numbers in IMPORT.md come from the model itself.
BELLY_NOTES = {
    "vas_": "the path starts at the model's effective origin on the femoral shaft, but the vasti arise along most of "
            "the femur: the anatomical belly is longer and slimmer than the path allows. Not lengthened beyond the path",
    "glut_med": "one of three lines standing for a fan from the iliac crest to the greater trochanter: each line "
                "carries a third of the fan's volume over the fan's short radius",
    "glut_min": "one of three lines standing for a fan under gluteus medius: a short, thick share of the fan",
    "glut_max": "one of three lines standing for a broad sheet from ilium, sacrum and coccyx to the femur",
    "quad_fem": "quadratus femoris is short and thick in anatomy too (a quadrilateral block from the ischial "
                "tuberosity to the intertrochanteric crest)",
    "gem": "the gemelli are short muscles in anatomy too (ischium to the greater trochanter)",
    "ercspn": "one actuator standing for the whole column of spinal extensors (2500 N) over the 15 cm from pelvis "
              "to torso: the volume of many muscles on one short line",
    "TRImed": "the medial head arises along the back of the humeral shaft: the model's effective origin leaves a "
              "short path, as for the vasti. Not lengthened beyond the path",
    "TRIlat": "the lateral head arises along the back of the humeral shaft: the model's effective origin leaves a "
              "short path. Not lengthened beyond the path",
    "BRA": "brachialis arises along the lower half of the humerus: a short, thick muscle over the elbow",
    # MuJoCo's MyoSuite models (myo-sim): names as there
    "glmed": "one of three lines standing for the gluteus medius fan from the iliac crest to the greater trochanter",
    "glmin": "one of three lines standing for the gluteus minimus fan under gluteus medius",
    "SUBSC": "subscapularis fills the subscapular fossa: a broad flat sheet drawn as one short line to the humerus",
    "INFSP": "infraspinatus fills the infraspinous fossa: a broad sheet drawn as one short line to the humerus",
    "PQ": "pronator quadratus is a flat square across the distal forearm, shorter than it is wide in anatomy too",
    "ANC": "anconeus is a small triangle behind the elbow, short and thick in anatomy too",
    "OP": "opponens pollicis is a short thick thenar muscle over the first metacarpal",
    "MF_": "a multifidus slip: short fascicles spanning two to four vertebrae, with a large force on a short path",
}


def belly_note(muscle: str) -> str | None:
    """The anatomical reason a muscle's belly is short or squat, or None if none is recorded."""
    base = SIDE_SUFFIX.sub("", muscle)
    for key, note in BELLY_NOTES.items():
        if base == key or (key.endswith("_") and base.startswith(key)) or base.startswith(key):
            return note
    return None


def _volume_law(st: dict, ms: list[dict]) -> list[str]:
    """The volume law's line when the import sized muscles by a subject's regression."""
    v = st.get("volumes")
    if not v:
        return []
    n = sum(m.get("volume_law") == "handsfield2014" for m in ms)
    return ["", f"Volumes of {n} of {len(ms)} muscles (`volume_law` in import_report.json) by the regression of "
            f"Handsfield et al. (2014) on height and mass, for a {v['height_m']:g} m, {v['mass_kg']:g} kg subject "
            f"(one lower limb's muscles: {v['lower_limb_total_cm3']:.0f} cm³; a paper muscle made of several model "
            "muscles is split by their max forces); the others by PCSA × optimal fibre length (docs/IMPORTERS.md, "
            "\"Belly volumes\")."]


def belly_markdown(r: dict, fibre_words: str = "optimal fibre length") -> list[str]:
    """IMPORT.md's "Bellies" section: the law (its optimal fibre length named ``fibre_words``),
    the library's slenderness, and every short or squat belly with its numbers and reason."""
    ms = r["muscles"]
    if not ms:
        return ["", "## Bellies", "", "No muscles."]
    sl = [m["slenderness"] for m in ms]
    st = r["settings"]
    lines = ["", "## Bellies", "",
             f"Law (docs/METHOD.md, \"Choices in detail\"): PCSA = max isometric force / {st['specific_tension_Pa'] / 1e6:g} MPa; "
             f"belly volume = PCSA × {fibre_words}; free tendon = "
             f"{st['free_tendon_share']:g} × tendon slack length (the rest of it is aponeurosis, inside the belly), "
             "shortened where the belly would not hold its fibres (optimal fibre length × cos pennation); "
             "belly length = rest path − free tendon; tendon Ø from max force at "
             f"{st['tendon_stress_Pa'] / 1e6:g} MPa. Colours: {st['palette']} palette.", *_volume_law(st, ms), "",
             f"Slenderness at rest (length where the cross-section is at least half its widest, over the widest "
             f"diameter; `axdf_cli/model/measure.py`): min {min(sl):.2f}, median {float(np.median(sl)):.2f}, "
             f"below 1.2: {sum(x < 1.2 for x in sl)}, below {SQUAT_BELLY:g}: {sum(x < SQUAT_BELLY for x in sl)} "
             f"of {len(sl)}.", ""]
    short = [m for m in ms if m["slenderness"] < SHORT_BELLY or m["belly_length"] < m["fibre_projection"] * (1 - 1e-6)]
    if not short:
        return lines + ["Every belly is at least twice as long as it is wide."]
    lines += [f"Short or squat bellies (slenderness below {SHORT_BELLY:g}, or a path shorter than the fibres):", ""]
    for m in short:
        d_mean = 2.0 * math.sqrt(m["volume_m3"] / (math.pi * m["belly_length"]))
        why = [f"belly {m['belly_length'] * 100:.1f} cm of a {m['rest_path_length'] * 100:.1f} cm path "
               f"(free tendon {m['free_tendon'] * 100:.1f} cm) holds {m['volume_m3'] * 1e6:.0f} cm³ "
               f"(PCSA {m['pcsa_m2'] * 1e4:.1f} cm² × fibres {m['optimal_fiber_length'] * 100:.1f} cm): "
               f"mean Ø {d_mean * 100:.1f} cm"]
        if m["belly_length"] < m["fibre_projection"]:
            why.append(f"the path is shorter than the fibres ({m['fibre_projection'] * 100:.1f} cm along it): "
                       "the model's origin-to-insertion line is shorter than the muscle; not lengthened")
        if "thinned_from_radius" in m:
            why.append(f"thinned from Ø {m['thinned_from_radius'] * 2e3:.1f} mm (the law's volume on this path) to "
                       f"Ø {m['belly_radius'] * 2e3:.1f} mm, slenderness {m['slenderness']:.2f}: "
                       f"{m['rest_volume_m3'] * 1e6:.0f} cm³ instead of {m['volume_m3'] * 1e6:.0f} cm³")
        note = belly_note(m["muscle"])
        if note:
            why.append(note)
        lines.append(f"- **{m['muscle']}** (slenderness {m['slenderness']:.2f}"
                     f"{', squat' if m['slenderness'] < SQUAT_BELLY else ''}): " + "; ".join(why) + ".")
    return lines


#: IMPORT.md's muscle table: column → (header, the report row's key, factor, format); a list
#: value is counted, a factor of None writes the value as it is.
COLUMNS = {
    "muscle": ("muscle", "muscle", None, ""), "path_points": ("path points", "path_points", None, ""),
    "sites": ("sites", "path_points", None, ""), "wrap_geoms": ("wrap geoms", "wraps", None, ""),
    "control_points": ("control points", "control_points", None, ""), "force": ("force (N)", "force", 1, ".0f"),
    "rest_path": ("rest path (cm)", "rest_path_length", 100, ".1f"), "pcsa": ("PCSA (cm²)", "pcsa_m2", 1e4, ".2f"),
    "fibres": ("fibres (cm)", "optimal_fiber_length", 100, ".1f"), "belly": ("belly (cm)", "belly_length", 100, ".1f"),
    "free_tendon": ("free tendon (cm)", "free_tendon", 100, ".1f"), "belly_d": ("belly Ø (mm)", "belly_radius", 2e3, ".1f"),
    "tendon_d": ("tendon Ø (mm)", "tendon_radius", 2e3, ".1f"), "slenderness": ("slenderness", "slenderness", 1, ".2f"),
}


def _cell(m: dict, key: str, factor, fmt: str) -> str:
    v = m[key]
    if isinstance(v, list):
        v = len(v)
    return f"{v}" if factor is None else f"{v * factor:{fmt}}"


def import_markdown(r: dict, intro: list[str], poses: str, rules) -> str:
    """IMPORT.md of a model import: its title and source, the format's ``intro`` lines, the
    muscles whose axes were raised over ``poses``, warnings, what was not imported, the
    bellies and the muscle table (``rules.columns``, ``rules.fibre_words``)."""
    lines = [f"# Import of {r['source']['model']} (`{r['skeleton']}`)", ""] + intro
    lines += axis_markdown(r, poses)
    lines += ["## Warnings", ""] + ([f"- {w}" for w in r["warnings"]] or ["- none"]) + [""]
    lines += ["## Not imported", "", "| kind | name | where | why |", "|---|---|---|---|"]
    lines += [f"| {i['kind']} | {i['name']} | {i['where']} | {i['why']} |" for i in r["ignored"]] or \
        ["| – | – | – | nothing |"]
    lines += belly_markdown(r, rules.fibre_words)
    cols = [COLUMNS[c] for c in rules.columns]
    lines += ["", "## Muscles", "", "| " + " | ".join(c[0] for c in cols) + " |", "|" + "---|" * len(cols)]
    lines += ["| " + " | ".join(_cell(m, *c[1:]) for c in cols) + " |" for m in r["muscles"]]
    return "\n".join(lines) + "\n"
