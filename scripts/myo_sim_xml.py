"""Write a MyoSuite model of the installed ``myo-sim`` package as one standalone MJCF file.

``myo-sim`` (MyoSuite's models, Apache-2.0) composes its models from fragments in memory
(``myo_sim.load_spec(NAME)``: torso scaffold, arms, legs, mirrored left arm); there is no
single XML file of ``myoarm`` or ``myofullbody`` in the package. MuJoCo writes the composed
spec as XML (``MjSpec.to_xml``), but the file it writes for an attached spec does not load
in MuJoCo again: the attached model's top-level default becomes a ``<default>`` without a
class (MuJoCo: "empty class name"), and the mirrored arm repeats the arm's classes
("repeated default class name"). This script names the first (``myo_sim_default<N>``) and
drops the repeats (checked to be identical to the class they repeat but for colours), so that MuJoCo loads
the file, and ``axdf import mjcf`` reads the same file MuJoCo judges.

    python scripts/myo_sim_xml.py myoarm out/mjcf/myoarm.xml

Meshes stay where the package has them (the file's ``meshdir`` is the package's models
folder). Needs ``mujoco`` and ``myo-sim`` (the test extra).
"""
from __future__ import annotations

import sys
import warnings
import xml.etree.ElementTree as ET
from pathlib import Path


#: Attributes that only colour a geom: the mirrored arm's defaults differ from the arm's in
#: these alone (``material="MatSkin_l"``), so its repeated classes are dropped all the same.
VISUAL_ONLY = frozenset({"material", "rgba", "texture"})


def _same(a: ET.Element, b: ET.Element) -> bool:
    def attrs(e):
        return {k: v for k, v in e.attrib.items() if k not in VISUAL_ONLY}

    return a.tag == b.tag and attrs(a) == attrs(b) and len(a) == len(b) and all(_same(x, y) for x, y in zip(a, b))


def fix_defaults(xml: str) -> str:
    """MJCF text with unnamed nested defaults named and repeated default classes removed."""
    root = ET.fromstring(xml)
    seen: dict[str, ET.Element] = {}
    count = 0

    def walk(node: ET.Element, depth: int):
        nonlocal count
        for child in list(node):
            if child.tag != "default":
                continue
            cls = child.get("class")
            if cls is None and depth > 0:
                count += 1
                cls = f"myo_sim_default{count}"
                child.set("class", cls)
            if cls is not None and cls in seen:
                if not _same(seen[cls], child):
                    raise SystemExit(f"default class {cls!r} is repeated with other values")
                node.remove(child)
                continue
            if cls is not None:
                seen[cls] = child
            walk(child, depth + 1)

    for d in root.findall("default"):
        walk(d, 1) if d.get("class") is None else walk(root, 0)
    ET.indent(root, space="  ")
    return ET.tostring(root, encoding="unicode") + "\n"


def export(name: str) -> str:
    """The MJCF text of the myo-sim model ``name`` (``myoarm``, ``myolegs``, ``myofullbody`` ...)."""
    import myo_sim

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # "Attaching a spec with an empty prefix ...": what fix_defaults repairs
        return fix_defaults(myo_sim.load_spec(name).to_xml())


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if len(argv) != 2:
        print("usage: python scripts/myo_sim_xml.py NAME OUT.xml", file=sys.stderr)
        return 2
    out = Path(argv[1])
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = out.with_name(out.name + ".tmp")
    tmp.write_text(export(argv[0]))
    tmp.replace(out)
    print(out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
