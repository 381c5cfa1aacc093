"""The tools' own constants (``axdf retarget``, ``axdf pack``, ``axdf skin``, ``axdf fit``,
``axdf atlas``: the commands that write axdf files), each with the reason for its value.

They live here, in the tools' room, and not in :mod:`axdf_cli.tolerances`, because no run
reads them: a run's identity (``axdf_cli.pipeline.manifest.run_identity``, what ``--resume``
compares) records every constant of :mod:`axdf_cli.tolerances` and the bytes of that file, so a
fitting constant there would refuse the resume of every run. A constant that a run's numbers
depend on belongs in :mod:`axdf_cli.tolerances` (tests/test_run_identity.py checks the split).
"""

# ----------------------------------------------------------------------------- axdf skin
# `axdf skin` refuses a skeleton with a fitted segment shorter than SKIN_MIN_SEGMENT metres (a
# zero offset: the fit's map along it is undefined, and the body came out NaN).
SKIN_MIN_SEGMENT = 0.01

# ----------------------------------------------------------------------------- axdf retarget
# Scaling the model to the subject (`scale: fit`): a pair of mapped points is a segment when its
# distance changes by less than SEGMENT_MODEL_RIGIDITY (relative) over sampled poses of the model
# (gait2392's coupled knee translations move the hip-knee distance by up to 7% over the knee's
# whole range, 2.5% over a walk: the thighs count, and they carry the legs' proportions) and by less than
# SEGMENT_MOCAP_RIGIDITY between the 10th and 90th percentile of the motion (marker noise and
# soft tissue: a few per cent), and is at least SEGMENT_MIN_LENGTH metres long in both.
SEGMENT_MODEL_RIGIDITY = 0.08
SEGMENT_MOCAP_RIGIDITY = 0.05
SEGMENT_MIN_LENGTH = 0.02
# Poses sampled to find the model's rigid pairs and points rigid with the root (seeded, fixed).
SEGMENT_SAMPLES = 16
# A point is rigid with the root bone when it moves by less than this (metres) in the root's frame
# over the sampled poses.
ROOT_RIGID = 1e-6
# The scale is measured on at most this many frames of the motion (evenly spaced: the median
# and percentiles of a segment's length settle long before; it bounds the work of long takes).
SEGMENT_MAX_FRAMES = 2000
# A retarget map has at most this many points (the scale's segments are pairs of points:
# their work grows as the square). Marker sets have 40-100 markers, whole-body keypoint sets
# (COCO-WholeBody, SMPL-X joints) up to ~130.
RETARGET_MAX_POINTS = 256
# A segment whose motion length over the scaled model's is off the segments' median ratio by
# more than this factor is a map mistake, not a subject's proportion (CMU 131 on gait2392 spans
# 0.86-1.11; a point `at: [6, 0, 0]` meant as [0.06, 0, 0] is 100 times off): refused, naming
# the point. A fitted scale outside RETARGET_SCALE_BAND (a subject less than half or more than
# twice the model's size) is warned: a motion in the wrong unit (a BVH in inches read as CMU
# units, or the reverse) gives 0.43 or 2.2.
RETARGET_SEGMENT_OUTLIER = 2.0
RETARGET_SCALE_BAND = (0.5, 2.0)
# A fit is warned on (axdf retarget; --strict refuses it) when its error exceeds these shares of
# the subject's height (head top to sole: axdf_cli.model.stature.stature of the motion's own
# skeleton, or of the model's times the scale; the leg from hip to ankle is 0.491 of it): the
# take's RMS over every weighted point beyond RETARGET_RMS_SHARE (1.5%: 3% of the leg), a frame's
# RMS beyond RETARGET_FRAME_SHARE (3.7%: 7.5% of the leg; the shipped CMU walk's worst, its crouch
# with the knee at its 120 deg limit, is 2.9% of the subject's 1.54 m), or one point's error in a
# frame beyond RETARGET_POINT_SHARE (9.8%: 20% of the leg; the walk's worst 7%). (Until the one
# height, these were shares of the map's points' vertical extent, 1.33 m for the walk: 1.8%,
# 4.5% and 12%, the same millimetres within 4%.) A coordinate of the root bone
# at a range's end in any frame, or any other coordinate in more than RETARGET_PINNED_SHARE of
# the frames (the walk's subtalar joints: 18%), is warned too.
RETARGET_RMS_SHARE = 0.015
RETARGET_FRAME_SHARE = 0.037
RETARGET_POINT_SHARE = 0.098
RETARGET_PINNED_SHARE = 0.25

# ----------------------------------------------------------------------------- axdf pack
# `axdf pack --pose`: the polish also runs at this many of the pose's frames (evenly spaced;
# every frame of a shorter pose), and fits the mean of its displacements there and at rest.
PACK_POSE_FRAMES = 16
# `axdf pack` holds about PACK_BYTES_PER_VERTEX of memory per muscle vertex at once (distance
# queries, territories, fits); a pack of more than PACK_MAX_VERTICES vertices (about 6.4 GiB)
# is refused before any work. gait2392's 92 muscles at the default 40x24 hold 88,320; a single
# muscle at the spec's limit (1000x1000) would need about 27 GB.
PACK_BYTES_PER_VERTEX = 27 * 1024
PACK_MAX_VERTICES = 250_000

# ----------------------------------------------------------------------------- axdf skin
# The fitted body's height (head top to sole) and the skeleton's stature may differ by this
# share before `axdf skin` warns (the bound).
SKIN_HEIGHT_TOLERANCE = 0.03
# Weights a skeleton bone gets on a vertex below this are dropped (and the rest renormalised):
# under 1e-3 of a bone's motion moves a vertex of a body-sized mesh by under a millimetre.
SKIN_WEIGHT_MIN = 1e-3
# Passes of neighbour averaging that soften the fat map's steps between regions (each pass
# spreads a step over about one edge, ~1-2 cm on the body).
SKIN_FAT_SMOOTHING = 6
# --push: rounds of moving the rest skin outward over muscle vertices that lie outside it, the
# clearance they are given (metres: the skin ends at least this far outside the muscle), and
# passes of neighbour averaging that spread each push over the skin around it (no dents or spikes).
SKIN_PUSH_ROUNDS = 8
SKIN_PUSH_CLEARANCE = 0.002
SKIN_PUSH_SMOOTHING = 4

# ----------------------------------------------------------------------------- axdf fit, axdf atlas
# `axdf fit` (axdf_cli/tools/fit.py, fit_sections.py): a closed muscle mesh → an AxDf muscle.
# Sections by default: measured on the Visible Human atlas (docs/FIT.md), 16 sections follow
# the muscles' bellies to IoU 0.9+ where 8 leave a few points of overlap; the bounds keep the
# spec's limit (64 sections) and a surface that tapers (at least 3 sections between poles).
FIT_SECTIONS_DEFAULT = 16
FIT_SECTIONS_MIN = 3
FIT_SECTIONS_MAX = 64
# Surface samples a fit reads the mesh by (area-uniform, seeded: the same mesh gives the same
# file): 6,000 put a sample every ~2 mm on a gluteus maximus' ~600 cm^2 of surface.
FIT_SAMPLES = 6000
FIT_SEED = 0
# The medial axis: slabs of samples per round and rounds of slabs perpendicular to the current
# curve (2 settle a curved sartorius; more change it by well under a millimetre); the dense
# polyline a sample finds its nearest curve point on; the share of the length at each end whose
# samples' centroid places the tip (the surface's pole).
FIT_AXIS_SLABS = 24
FIT_AXIS_ROUNDS = 3
FIT_AXIS_DENSE = 400
FIT_TIP_SHARE = 0.03
# Cut outlines: rays per cut (from the axis, the farthest crossing), points per outline around
# the surface (4 per control point), cutting planes per section (plus 2 sections' worth beyond
# the ends), the phase search's steps (over half a control point's spacing each way).
FIT_RAYS = 96
FIT_AROUND = 32
FIT_PLANES_PER_SECTION = 4
FIT_PHASE_STEPS = 17
# Rounds of closest-point refinement after the cut outlines (each both ways: the surface's
# samples to their closest mesh points, the mesh's samples to the surface's nearest sample),
# point to plane (along the mesh's normal, so the surface may slide along it) with a small
# weight of point to point that keeps the net from drifting where the plane terms say nothing.
# Measured on 7 atlas muscles at 16 sections: point to point alone needs 20+ rounds for IoU
# 0.92-0.94; point to plane reaches 0.95-0.97 in 8 (weight 0.1: 0.94; 0.02: 0.95; 0.005: 0.955
# on vastus lateralis). The smoothing of control points along the muscle (second differences,
# relative to the data's weight) keeps rows near the tips, where cuts are tiny and few, from
# folding; small enough to change an IoU by < 0.005. The smoothing round each section (second
# differences round its loop, relative to the data's weight, raised where the data sees the
# section less): at 1e-3 the tip sections of soleus, vastus lateralis and gluteus maximus stop
# crumpling (control polygons with 3+ concave corners: 12 of 48 sections at 1e-4, 5) for an IoU
# 0.001-0.003 lower; 1e-2 costs 0.015.
FIT_REFINE_ROUNDS = 8
# The rows' design matrix is dense up to this many bytes (16 sections: 57 MB, as fitted for the
# shipped atlas library), sparse beyond (the same entries): dense, 64 sections took 196 s and
# 2.95 GB on a 642-vertex mesh, the dense products growing as N^2.
FIT_DENSE_DESIGN_BYTES = 64 * 2**20
FIT_SMOOTH = 1e-3
FIT_POINT_WEIGHT = 0.005
FIT_SMOOTH_AROUND = 1e-3
# The written surface's resolution: rows along per section (+ 8, at least FIT_ALONG_MIN) and
# vertices around, fine enough that the tessellation of the fitted surface changes its
# measured IoU by < 0.01.
FIT_ALONG_PER_SECTION = 4
FIT_ALONG_MIN = 40
FIT_OUTPUT_AROUND = 32
# Tendons: the sections at each end thinner than this share of the widest section's area make
# the tendon (its radial size kept when the muscle stretches); at most FIT_TENDON_MAX of the
# length in all (the spec allows < 0.95: a belly must remain).
FIT_TENDON_AREA_SHARE = 0.1
FIT_TENDON_MAX = 0.6
# A mesh encloses no volume below this share of its bounding box (a flat or degenerate
# surface), or below this many m^3 (a point).
FIT_MIN_VOLUME_SHARE = 1e-6
FIT_MIN_VOLUME = 1e-15
# A fitted mesh's size, read in --units: its longest extent within [FIT_MIN_SIZE, FIT_MAX_SIZE]
# metres and no vertex farther than FIT_MAX_REACH from the skeleton's origin. Muscles run from a
# few millimetres (the hand's lumbricals, 5 mm across) to half a metre (sartorius); a mesh in
# millimetres read as metres is a thousand times too large, one in metres read as millimetres
# a thousand times too small, so the refusal names --units.
FIT_MIN_SIZE = 0.002
FIT_MAX_SIZE = 3.0
FIT_MAX_REACH = 10.0
# A mesh lies in the skeleton's rest frame when some point of it comes within this distance
# (metres) of a bone at rest (its mesh, or where the skeleton has none its segment to its
# children): a muscle attaches to bones. Measured at rest on gait2392: the fitted atlas library's
# and the OpenSim import's muscles come within 32 mm of a bone mesh at most (bifemlh_l), within
# 92 mm of a bone segment (the obliques, from the torso's origin); the Visible Human's meshes in
# their scan frame (mm) lie 389-681 mm from every bone, which is what this refuses.
FIT_MAX_BONE_GAP = 0.15
# A mesh's closed pieces under this share of its volume are segmentation slivers, dropped (and
# reported); a second piece above it is a second muscle, refused. Measured on the atlases: the
# slivers' largest share is 1.7% (BodyParts3D's internal oblique, 617 pieces; external oblique
# 43 pieces, 0.02%), the real second pieces 13.6% and more (spinalis; flexor digitorum
# superficialis 26%, latissimus dorsi 34%, extensor carpi ulnaris 38%).
FIT_MIN_PIECE_SHARE = 0.05
# A --transform's 3x3 part is refused as singular when its smallest singular value is below
# this share of its largest (it would flatten the mesh).
FIT_TRANSFORM_MIN_SINGULAR = 1e-6
# The fit's measures: the IoU grid's spacing (metres; coarser only to stay within the point
# budget), surface samples for the distances.
FIT_IOU_SPACING = 0.002
FIT_IOU_MAX_POINTS = 4_000_000
# A small muscle's IoU grid: where the thinnest side of the box around the mesh and its fit holds
# fewer than FIT_IOU_MIN_CELLS cells of FIT_IOU_SPACING, the grid has FIT_IOU_SMALL_CELLS cells
# across that side instead (a 2 mm grid read a 3.3 mm muscle fitted to 0.001 mm as IoU 0.00).
# Every fit of the shipped atlas library has 6.5+ cells of 2 mm across (flexor digitorum
# longus, 13 mm), so its measures are unchanged.
FIT_IOU_MIN_CELLS = 6
FIT_IOU_SMALL_CELLS = 48
FIT_MEASURE_SAMPLES = 20000
# A fit whose IoU with its mesh is below this is warned of (the bound for the worst
# muscle of a library; the atlas' leg fits at 0.87+ with 8 sections): the mesh is not one belly
# along one axis (a ring, a branching or C-shaped muscle; docs/FIT.md).
FIT_WARN_IOU = 0.75

# --- the atlas registered onto a skeleton (axdf_cli/tools/atlas.py; docs/FIT.md "Atlas onto a skeleton")
# samples per atlas bone for the warp's closest points: enough to follow a tibia's crest, few
# enough that a thin-plate spline round solves in seconds
ATLAS_BONE_SAMPLES = 400
# rounds of closest points + thin-plate spline; the residual stops falling after about 4
ATLAS_WARP_ROUNDS = 5
# the thin-plate spline's smoothing (scipy's RBFInterpolator, per closest-point pair; the
# landmarks have none): chosen by measurement (docs/FIT.md): 1e-6 leaves the bones' samples
# 0.04-0.2 mm off the model's on average, 1e-4 0.7-1 mm, with no fold either way
ATLAS_WARP_SMOOTHING = 1e-6
# points per evaluation of the warp (memory: chunk x centres x 8 bytes)
ATLAS_WARP_CHUNK = 20000
# the other hip's weight in the landmarks' similarity: it only turns the leg about its long
# axis (hip, knee and ankle are nearly on a line); at full weight the atlas' narrower pelvis
# pulls the leg's scale and leaves 2-3 cm at every joint
ATLAS_OTHER_HIP_WEIGHT = 0.1
# how far beyond a bone's surface a warped atlas muscle vertex found inside the bone is put
# (the warp leaves the model's coarse bones 1-3 mm off the atlas' where a muscle lies on them)
ATLAS_BONE_MARGIN = 0.001
# the grid spacing (m) on which an atlas muscle shared by a model group (gluteus maximus ->
# glut_max1..3) is cut into closed parts (winding number, marching cubes)
ATLAS_SPLIT_SPACING = 0.0015
# an atlas muscle's fit is shipped only with at least this IoU with its mesh and its volume
# within this factor of the mesh's; else the model's own muscle is kept (the left flexor
# hallucis longus, whose tendon turns under the foot, fits at IoU 0.1 with 47x its volume;
# the thin extensors that fit at 0.6-0.75 keep their volume within 25%; adductor magnus'
# middle part, a C-shaped slab after the cut, fits at 0.6 with 0.62-0.63 of its volume)
ATLAS_MIN_IOU = 0.5
ATLAS_MAX_VOLUME_FACTOR = 1.5
