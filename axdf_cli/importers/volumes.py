"""Muscle volumes from the subject's height and mass: the regression of Handsfield et al. (2014).

Handsfield, Meyer, Hart, Abel & Blemker, "Relationships of 35 lower limb muscles to height and
body mass quantified using MRI", Journal of Biomechanics 47(3):631-638, 2014. Twenty-four
subjects' lower limb muscles were segmented from MRI. The paper's regressions give

- the total volume of the limb's muscles, V_total = 47.0 cm³/(m·kg) × height × mass + 1285 cm³;
- each muscle's volume, V = b1 × V_total + b2 (its supplementary table of 35 muscles).

``axdf import osim|mjcf --volumes handsfield --height M --mass KG`` sizes a model's lower limb
muscles by them instead of by PCSA × optimal fibre length (docs/IMPORTERS.md, "Belly volumes").
A model muscle that is part of one of the paper's muscles (gait2392's three gluteus maximus
heads, Rajagopal's four adductor magnus heads, the peronei, the toe extensors) takes its
share of that muscle's volume in proportion to its max isometric force. Muscles the paper did
not measure (trunk, arm) keep the PCSA law.
"""
from __future__ import annotations

import re
from dataclasses import dataclass

#: V_total = TOTAL_SLOPE × height (m) × mass (kg) + TOTAL_INTERCEPT, cm³ (Handsfield 2014, Fig. 2).
TOTAL_SLOPE = 47.0
TOTAL_INTERCEPT = 1285.0

#: The paper's 35 muscles: name, b1 (share of V_total), b2 (cm³), and the model muscles that
#: make it up, as regular expressions on the name without its side suffix: OpenSim's gait2392
#: names, then Rajagopal 2016's (also MyoSuite's legs). None: no model muscle of that family.
HANDSFIELD = (
    ("gluteus maximus", 0.123, -25.4, r"glut_max\d", r"glmax\d"),
    ("adductor magnus", 0.0793, -4.7, r"add_mag\d", r"addmag(Dist|Isch|Mid|Prox)"),
    ("gluteus medius", 0.0478, -16.9, r"glut_med\d", r"glmed\d"),
    ("psoas", 0.055, -117.0, r"psoas", r"psoas"),
    ("iliacus", 0.0248, 0.383, r"iliacus", r"iliacus"),
    ("sartorius", 0.0256, -18.2, r"sar", r"sart"),
    ("adductor longus", 0.0259, -21.9, r"add_long", r"addlong"),
    ("gluteus minimus", 0.0129, 12.6, r"glut_min\d", r"glmin\d"),
    ("adductor brevis", 0.0137, 6.2, r"add_brev", r"addbrev"),
    ("gracilis", 0.0138, 6.07, r"grac", r"grac"),
    ("pectineus", 0.0107, -9.94, r"pect", None),
    ("tensor fasciae latae", 0.0136, -31.5, r"tfl", r"tfl"),
    ("obturator externus", 0.00349, 28.3, None, None),
    ("piriformis", 0.00372, 16.2, r"peri", r"piri"),
    ("quadratus femoris", 0.00475, -1.45, r"quad_fem", None),
    ("obturator internus", 0.00252, 8.68, None, None),
    ("small external rotators", 0.00172, 3.85, r"gem", None),
    ("vastus lateralis", 0.125, -55.7, r"vas_lat", r"vaslat"),
    ("vastus medialis", 0.0631, -16.3, r"vas_med", r"vasmed"),
    ("vastus intermedius", 0.0273, 76.5, r"vas_int", r"vasint"),
    ("rectus femoris", 0.0371, 4.97, r"rect_fem", r"recfem"),
    ("semimembranosus", 0.0319, 18.2, r"semimem", r"semimem"),
    ("biceps femoris long head", 0.0256, 24.3, r"bifemlh", r"bflh"),
    ("semitendinosus", 0.0285, -16.8, r"semiten", r"semiten"),
    ("biceps femoris short head", 0.016, -13.8, r"bifemsh", r"bfsh"),
    ("popliteus", 0.00298, 2.11, None, None),
    ("soleus", 0.0507, 78.2, r"soleus", r"soleus"),
    ("medial gastrocnemius", 0.0348, 9.42, r"med_gas", r"gasmed"),
    ("lateral gastrocnemius", 0.0199, 8.21, r"lat_gas", r"gaslat"),
    ("tibialis anterior", 0.0161, 20.3, r"tib_ant", r"tibant"),
    ("peroneals (brevis, longus)", 0.0194, -7.43, r"per_(brev|long)", r"per(brev|long)"),
    ("tibialis posterior", 0.0104, 30.8, r"tib_post", r"tibpost"),
    ("extensors (digitorum longus, hallucis longus)", 0.0132, 8.7, r"ext_(dig|hal)|per_tert", r"edl|ehl"),
    ("flexor hallucis longus", 0.0137, -18.9, r"flex_hal", r"fhl"),
    ("flexor digitorum longus", 0.00259, 11.6, r"flex_dig", r"fdl"),
)

#: The subjects the regression holds for: the paper's (heights 1.48-1.93 m, masses 46-109 kg),
#: widened to what an adult model may be; outside it the flags are refused.
HEIGHT_RANGE = (1.0, 2.5)
MASS_RANGE = (20.0, 250.0)
_SIDE = re.compile(r"(?P<base>.+?)(?P<side>_[rl])?", re.S)  # (fullmatch: the whole name)


@dataclass(frozen=True)
class Subject:
    """The body whose muscles are sized: height (m) and mass (kg)."""

    height: float
    mass: float

    @property
    def total_cm3(self) -> float:
        """The regression's volume of one lower limb's muscles (cm³)."""
        return TOTAL_SLOPE * self.height * self.mass + TOTAL_INTERCEPT


@dataclass(frozen=True)
class Sized:
    """A muscle's regression volume (m³) and the paper's muscle it is (a share of)."""

    volume: float
    group: str
    share: float  # of the group's volume (1: the whole muscle)


def _group_of(base: str) -> str | None:
    for name, _b1, _b2, *patterns in HANDSFIELD:
        if any(p is not None and re.fullmatch(p, base) for p in patterns):
            return name
    return None


def regression_volumes(muscles: list, subject: Subject) -> dict[str, Sized]:
    """Each lower limb muscle's volume by the regression: ``muscles`` are the importer's
    (name, force) pairs. A paper muscle made of several model muscles on one side is split by
    their forces; a muscle of no paper muscle is left out (it keeps the PCSA law)."""
    coef = {name: (b1, b2) for name, b1, b2, *_ in HANDSFIELD}
    groups: dict[tuple[str, str], list[tuple[str, float]]] = {}
    for name, force in muscles:
        m = _SIDE.fullmatch(name)
        group = _group_of(m["base"])
        if group is not None:
            groups.setdefault((group, m["side"] or ""), []).append((name, max(float(force), 0.0)))
    out = {}
    for (group, _side), members in groups.items():
        b1, b2 = coef[group]
        cm3 = b1 * subject.total_cm3 + b2
        total = sum(f for _, f in members)
        for name, force in members:
            share = force / total if total > 0 else 1.0 / len(members)
            out[name] = Sized(cm3 * share * 1e-6, group, share)
    return out
