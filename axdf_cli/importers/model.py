"""The neutral model every reader fills (OpenSim, MuJoCo, BVH) and :mod:`~axdf_cli.importers.emit`
writes: bodies as bones with their joints' DOFs and couplings, bone meshes, path muscles with
their wrap surfaces and Hill-type numbers, and a motion. Everything is in axdf units (metres,
degrees) and axdf names; functions are written as the skeleton file holds them.

What differs between formats but is no part of the model (the import's file comments, the
format's report and its IMPORT.md wording) travels with it as :class:`Rules` and plain text, so
that one emitter serves every reader.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

from axdf_cli.errors import Mark
from axdf_cli.model.jiggle import JiggleSpec


@dataclass
class Coordinate:
    """A skeleton coordinate: its own value (``default``, ``range``) or one that ``follows``
    another through ``function`` (a coupler: no default, no range)."""

    name: str
    type: str  # rotation | translation
    default: float | None = None
    range: tuple[float, float] | None = None
    follows: str | None = None
    function: dict | None = None  # the coupler's function, as the skeleton file writes it

    def doc(self) -> dict:
        if self.follows is not None:
            return {"type": self.type, "follows": {"coord": self.follows, "function": self.function}}
        d = {"type": self.type, "default": self.default}
        if self.range is not None:
            d["range"] = list(self.range)
        return d


@dataclass
class Dof:
    """One DOF of a bone: a rotation about or translation along ``axis``, driven by ``coord``
    (None: constant) through ``function`` (None: the coordinate itself)."""

    type: str
    axis: list
    coord: str | None = None
    function: dict | None = None

    def doc(self) -> dict:
        d: dict = {}
        if self.coord is not None:
            d["coord"] = self.coord
        d["type"] = self.type
        d["axis"] = self.axis
        if self.function is not None:
            d["function"] = self.function
        return d


@dataclass
class Bone:
    """A body: placed in its parent by ``offset``/``orient``, moved by its DOFs, then by the
    fixed ``post_offset``/``post_orient``. ``anchor_first``: the post offset is written before
    the DOFs (MuJoCo imports' layout; the order of keys only)."""

    name: str
    parent: str | None = None
    offset: list | None = None
    orient: list | None = None
    dofs: list[Dof] = field(default_factory=list)
    post_offset: list | None = None
    post_orient: list | None = None
    anchor_first: bool = False

    def doc(self, mesh: str | None = None) -> dict:
        b: dict = {"name": self.name}
        for key, v in (("parent", self.parent), ("offset", self.offset), ("orient", self.orient)):
            if v is not None:
                b[key] = v
        dofs = {"dofs": [d.doc() for d in self.dofs]} if self.dofs else {}
        post = {k: v for k, v in (("post_offset", self.post_offset), ("post_orient", self.post_orient))
                if v is not None}
        b.update({**post, **dofs} if self.anchor_first else {**dofs, **post})
        if mesh is not None:
            b["mesh"] = mesh
        return b


@dataclass(frozen=True)
class Hill:
    """A muscle's Hill-type numbers: max isometric force (N), optimal fibre length and tendon
    slack length (m), pennation at optimal fibre length (rad)."""

    max_force: float
    fibre_length: float
    tendon_slack: float
    pennation: float = 0.0


@dataclass
class Muscle:
    """A path muscle: its path points and wrap surfaces (:mod:`axdf_cli.model.paths` objects,
    axdf units), its Hill numbers, and what its file and report row say of its source.
    ``hill`` None: the numbers are not in the model, and ``fibre_share`` of the rest path
    is fibre, the rest of it tendon slack (``force`` N)."""

    name: str
    path: list
    wraps: list
    hill: Hill | None
    header: str  # the muscle file's comment
    row: dict = field(default_factory=dict)  # the report row's fields of the source format
    jiggle: JiggleSpec | None = None
    fibre_share: float = 0.0
    force: float = 0.0
    mark: Mark | None = None  # where the muscle is in its model (errors and warnings name it)


@dataclass
class Motion:
    """A pose: ``keys`` frame → {coordinate: value} (frames 0..frames-1), optional muscle
    ``activation`` {muscle: {frame: value}}. ``mark``: where a pose too large for a YAML
    file is reported (None: not checked), ``remedy`` the hint then."""

    name: str
    fps: float
    frames: int
    keys: dict[int, dict[str, float]]
    header: str  # the pose file's comment
    activation: dict | None = None
    mark: Mark | None = None
    remedy: str = ""


@dataclass(frozen=True)
class Rules:
    """How a format's import sizes its muscles and writes its report and IMPORT.md.

    ``report``: write ``import_report.json`` and ``IMPORT.md`` (model imports) or nothing but
    the skeleton and pose (motion capture). ``probe_ranges``: axes are measured on seeded poses
    in the joints' ranges besides the rest pose and the motion. ``min_slenderness``: squatter
    bellies are thinned. ``shortfall``: report rows carry the axis shortfall. ``columns``:
    IMPORT.md's muscle table (keys of ``emit.COLUMNS``). ``fibre_words``: how the law's optimal
    fibre length is named."""

    tool: str  # "axdf import osim"
    report: bool = True
    probe_ranges: bool = False
    min_slenderness: float = 0.0
    shortfall: bool = False
    columns: tuple[str, ...] = ()
    fibre_words: str = "optimal fibre length"


@dataclass
class ImportedModel:
    """What a reader makes of its inputs: the neutral model and its source's report.

    ``report`` holds the source's part (source, motion, settings); ``complete(report)`` adds
    what needs the sized muscles (``report["muscles"]``: counts). ``intro(report)`` gives
    IMPORT.md's opening lines, ``poses`` names the poses axes are measured on. ``strip``: the
    input paths that written text names by file name only. ``refuse_at``: a skeleton that axdf
    would not read back is refused there, naming the limit (None: the reader's error as is)."""

    name: str
    header: str  # the skeleton file's comment
    bones: list[Bone]
    rules: Rules
    coordinates: list[Coordinate] = field(default_factory=list)
    meshes: dict[str, bytes] = field(default_factory=dict)  # bone -> PLY bytes, in the order written
    muscles: list[Muscle] = field(default_factory=list)
    motion: Motion | None = None
    report: dict = field(default_factory=dict)
    warnings: list[str] = field(default_factory=list)
    ignored: list[dict] = field(default_factory=list)  # {kind, name, where, why}
    inputs: list[Path] = field(default_factory=list)  # listed in the manifest
    assets: list[Path] = field(default_factory=list)  # other files read (never an output)
    strip: list[Path] = field(default_factory=list)
    refuse_at: Mark | None = None
    complete: Callable[[dict], None] = lambda report: None
    intro: Callable[[dict], list[str]] = lambda report: []
    poses: str = ""


@dataclass(frozen=True)
class Outputs:
    """Where an import writes: ``out`` (its folder, the report's place) and the flags that
    move its parts (None: the default place under ``out``)."""

    out: Path
    skeleton: Path | None = None
    muscles: Path | None = None
    pose: Path | None = None
    meshes: Path | None = None
