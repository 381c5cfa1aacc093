"""All numeric tolerances and fixed sampling choices, each with the reason for its value."""

# Rotation-minimizing frames: the axis is sampled at this many points per knot span for the
# double-reflection recurrence (Wang et al. 2008, global error O(h^4)). 32 per span keeps the
# frame error below 1e-4 rad on every shipped muscle and on a quarter-turn helix per span
# (tests/test_rmf.py measures it against a 16x denser reference).
RMF_SAMPLES_PER_SPAN = 32
# Axes with many control points (muscle paths: up to 48) have short spans that turn little:
# beyond the first RMF_DENSE_SPANS spans, RMF_SAMPLES_PER_EXTRA_SPAN samples per span keep the
# same frame error at a quarter of the cost (tests/test_rmf.py checks imported path muscles).
RMF_DENSE_SPANS = 6
RMF_SAMPLES_PER_EXTRA_SPAN = 8


def rmf_samples(n_control_points: int) -> int:
    """Intervals of the RMF sampling for an axis of n control points (n - 2 knot spans)."""
    spans = n_control_points - 2
    dense = min(spans, RMF_DENSE_SPANS)
    return RMF_SAMPLES_PER_SPAN * dense + RMF_SAMPLES_PER_EXTRA_SPAN * (spans - dense)

# The frame error the issue asks for; tests check RMF_SAMPLES_PER_SPAN achieves it.
RMF_MAX_FRAME_ERROR_RAD = 1e-4

# Closest-point binding: Newton iterations on (P - C(t)).C'(t) = 0 from the best dense sample
# converge quadratically; 8 iterations reach machine precision on any shipped axis.
BIND_NEWTON_ITERS = 8
BIND_DENSE_SAMPLES_PER_SPAN = 64

# Gauss-Legendre points per knot span for axis arc length: a quadratic B-spline's speed is
# smooth inside a span, 8 points give ~1e-12 relative error.
LENGTH_GAUSS_POINTS = 8

# `volume: exact` promises |V/V0 - 1| < 0.5% on the written mesh. The cubic in the section
# scale is solved to 1e-10 relative: far below float32 rounding of the written vertices.
VOLUME_EXACT_PROMISE = 5e-3
VOLUME_SOLVE_RTOL = 1e-10
VOLUME_SOLVE_ITERS = 30

# Degenerate geometry: an axis shorter than this (metres) or a section scale outside
# [SCALE_MIN, SCALE_MAX] is reported as a per-muscle, per-frame warning.
MIN_AXIS_LENGTH = 1e-6
SCALE_MIN = 0.05
SCALE_MAX = 20.0

# Isometric tension law: the belly's area profile is multiplied by 1 + TENSION_GAIN*e*(2b-1),
# b = sin^2(pi*s) over the belly; see axdf_cli/model/muscle.py.
TENSION_GAIN = 0.6

# YAML safety limits: hostile documents (alias bombs, deep nesting, huge files).
YAML_MAX_BYTES = 16 * 1024 * 1024
# Any other input file (.osim, .vtp, .mot/.sto, bone meshes): read whole into memory, so
# bounded; the largest shipped one (a gait2392 bone mesh) is ~1 MB.
INPUT_MAX_BYTES = 256 * 1024 * 1024
YAML_MAX_NODES = 2_000_000
YAML_MAX_DEPTH = 64
# XML models (.osim, MJCF): elements nested deeper than this are refused (the readers walk the
# tree recursively; a real model nests bodies a few dozen levels, as BVH joints, at most 256)
XML_MAX_DEPTH = 256
# BVH motion capture is text too, but long takes are large (100 channels x 100k frames is
# ~100 MB): read up to this many bytes.
BVH_MAX_BYTES = 512 * 1024 * 1024
# A BVH without --units/--scale is taken to hold a person, STATURE_BAND metres tall (adults'
# stature, 1st to 99th percentile, both sexes: 1.45-1.95 m, with room). The person's stature
# is estimated from the rest joint span (the extent along BVH Y, up, of every joint and end
# site at rest) as span / STATURE_SPAN_RATIO: the span is shorter than the stature because the
# highest end site lies inside the head and a rest pose may splay the legs (CMU's conversions:
# span 1.37 m, Head's end site ~10 cm below the vertex, thighs 20 deg apart, for subject 131,
# whose 0.80 m hip-to-ankle legs at 0.49 of stature make ~1.6 m: 0.85); a T-pose whose top end
# site is the vertex (span = stature) reads 16% tall, still in the band for 1.2-1.8 m spans.
# The unit (m, cm, mm, in, CMU's 1/0.45 in) whose stature lands in the band is taken; when none
# does, lengths are scaled to TYPICAL_STATURE and a warning says so.
STATURE_BAND = (1.4, 2.1)
STATURE_SPAN_RATIO = 0.86
TYPICAL_STATURE = 1.7
# numbers whose magnitude exceeds this are refused (metres, degrees, frames alike)
MAX_ABS_NUMBER = 1e9
# The highest frame rate a pose may have (and an importer may write): 100 kHz is beyond any
# motion capture or simulation output we read; a rate past it is a unit mistake.
MAX_FPS = 100000.0
# Seeds (a data set's seed: and --seed): the same range in the file and on the command line,
# within the numbers every axdf file accepts.
MAX_SEED = 1_000_000_000

# Rendering (tests/test_render_output.py). A vertex projected with camera.json is checked
# against the EXR `id` and `Z` at the pixel containing it, when that pixel's centre falls
# inside one of the vertex's own front-facing projected triangles. The EXR depth is the
# camera z interpolated by the rasterizer in float32 (about 1e-7 relative per operation);
# it must match the exact depth of the triangle's plane at the pixel centre to 1e-4 relative.
RENDER_DEPTH_RTOL = 1e-4
# Rasterizers snap vertices to a sub-pixel grid (Mesa llvmpipe: 1/256 px); a pixel centre
# counts as inside a triangle only when at least this far (pixels) from each of its edges.
RENDER_EDGE_MARGIN_PX = 0.02

# Retargeting (axdf retarget, axdf_cli/model/ik.py). Each frame's least squares stops when
# the cost changes by less than IK_FTOL relative or the step by less than IK_XTOL relative
# (exact data is fitted to ~1 µm; mocap is good to ~1 mm), or after IK_MAX_EVALUATIONS
# (a warm-started frame takes 3-10).
IK_FTOL = 1e-10
IK_XTOL = 1e-10
IK_GTOL = 1e-10
IK_MAX_EVALUATIONS = 200
# The pull towards the previous frame (a retarget map's `smooth:` default), as residual metres
# per degree of a rotation: a 10 degree change between frames costs as much as 1 cm of joint
# centre error. Where the points decide a coordinate it is negligible (a 0.4 m lever moves its
# end 7 mm per degree, ~50 times the pull's weight in the cost: a lag of ~2% of a frame's
# change); it decides what the points barely tell: a hip's rotation about a nearly straight
# leg, a toe's flexion on a 5 cm lever (with a pull ten times weaker, CMU's noisy toe joints
# turn the toes through 60 degrees in a 30th of a second). Translations: 0.01 m per metre (the root is seen directly).
IK_SMOOTH_ROTATION = 1e-3
IK_SMOOTH_TRANSLATION = 1e-2
# A free coordinate within this share of its range's width of an end is reported as held there.
IK_AT_BOUND = 1e-6
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
# the mapped body's height (the vertical extent of the map's weighted points in the model's rest
# pose, times the scale; for a map from the toes to the head, a leg from hip to ankle is ~0.6 of
# it): the take's RMS over every weighted point beyond RETARGET_RMS_SHARE (1.8%: 3% of the leg),
# a frame's RMS beyond RETARGET_FRAME_SHARE (4.5%: 7.5% of the leg; the shipped CMU walk's worst,
# its crouch with the knee at its 120 deg limit, is 3.3%), or one point's error in a frame beyond
# RETARGET_POINT_SHARE (12%: 20% of the leg; the walk's worst 8%). A coordinate of the root bone
# at a range's end in any frame, or any other coordinate in more than RETARGET_PINNED_SHARE of
# the frames (the walk's subtalar joints: 18%), is warned too.
RETARGET_RMS_SHARE = 0.018
RETARGET_FRAME_SHARE = 0.045
RETARGET_POINT_SHARE = 0.12
RETARGET_PINNED_SHARE = 0.25

# A motion column of a coupled coordinate (a CoordinateCouplerConstraint's dependent) is
# not read: the skeleton computes it. When it strays from the coupler's function of its
# leader's column by more than this (OpenSim units, rad or m) the import warns. OpenSim's IK
# satisfies the constraint to its assembly accuracy (the Rajagopal run: < 1e-8 rad); the
# motion file's 8 printed decimals leave ~1e-8; 1e-5 rad (6e-4 deg, 10 µm) is far above
# both and far below anything visible.
COUPLED_COLUMN_ATOL = 1e-5

# Axis control points of imported path muscles (axdf import osim|mjcf; importers/emit.py
# axis_points_for). The axis is a quadratic B-spline fitted to the wrapped path, and it cuts
# the path's corners: a hamstring's 1.2 cm insertion hook at 111 degrees of knee flexion
# (Rajagopal2016's run: 1.25% short at the default 12 points), finger flexors that fold by up to
# 140 degrees over a few millimetres (MyoSuite's hands). Each muscle keeps the default count
# (8 + 4 per interior point and surface, at most 48) unless its axis length differs from the
# wrapped path's by more than AXIS_SHORTFALL_MAX in some measured pose; then it gets the first
# count that stays within: steps of AXIS_POINTS_STEP up to AXIS_POINTS_FINE_MAX (a bend needs
# a few more points near it, and every point costs evaluation time in every frame), then of
# AXIS_POINTS_COARSE_STEP up to AXIS_POINTS_MAX (the muscle spec's limit: 128 points put a knot
# every 0.8% of the path, ~2 mm of a finger flexor), or the best of them.
# AXIS_SHORTFALL_MAX is half of the 1% within which every imported muscle must match its
# simulator's own length (OpenSim's getLength, MuJoCo's ten_length): the rest is room for the
# wrapping's own tolerances and for poses the importer did not measure. The shipped gait2392
# walk and arm26 flexion stay within it at the default counts.
AXIS_SHORTFALL_MAX = 5e-3
AXIS_POINTS_STEP = 4
AXIS_POINTS_FINE_MAX = 48
AXIS_POINTS_COARSE_STEP = 16
AXIS_POINTS_MAX = 128
# The poses measured are the importer's choice. axdf import osim: the rest pose and the
# imported motion's frames, at most AXIS_FIT_FRAMES of them, evenly spread (the path moves
# smoothly: a 2000-frame sample of a long take misses no bend of it). axdf import mjcf (whose
# models come without a motion of their own): the same, and AXIS_PROBE_POSES poses with every
# ranged coordinate uniform in its range (seed AXIS_PROBE_SEED: the same poses every import),
# so that the whole range of every joint is covered.
AXIS_FIT_FRAMES = 2000
AXIS_PROBE_POSES = 64
AXIS_PROBE_SEED = 20

# Data-set keypoints (axdf_cli/model/keypoints.py): two keypoints closer than this (metres) at
# the rest pose are one point. Coincident by construction are BVH helper joints at offset 0
# from their parent (CMU's LHipJoint, lowerback, lowerneck, the collars, lhand, LThumb) and the
# radius's head 2 cm beside the humero-ulnar joint (human_r); distinct anatomical keypoints of
# the shipped skeletons are 2.8 cm apart or more (CMU's fingers' base to their end site).
KEYPOINT_MERGE = 0.025

# Contact (axdf_cli/model/contact.py). Muscles keep CONTACT_MARGIN apart and CONTACT_BONE_MARGIN
# off bones: the axis-space query reads the tessellated rings linearly, a little inside the
# curved surface between them, so a small gap keeps the written meshes apart.
CONTACT_MARGIN = 0.001
CONTACT_BONE_MARGIN = 0.001
# Jacobi passes (push, fit the rings' modes, re-solve the volume); a fixed number, so the result
# is a continuous function of the frame. More passes clear more overlap but, the volume being
# kept, press it into the next layer and follow the neighbours' motion more. Two passes clear
# about half of one pass's overlap with every vertex step within 1.5x the no-contact one (no
# pops); a third pass pops. The contact rows of `make bench` (docs/BENCH.md) measure it.
CONTACT_ITERATIONS = 2
# Over-relaxation of a pass's pushes: the muscles' pushes, the bones' and the thick muscles'
# giving way (to a thin muscle or a pole inside them) are asked for this many times over. A
# pass delivers only part of what its samples ask for at the deepest points (the rings' five
# modes and the smoothing along the muscle spread a local push, and the volume's re-solve
# gives some back), so two passes without it leave overlap they could clear. 2 on the
# muscles' pushes takes the worst step past 1.5x (a pop). A pole's own push out of a bone is
# asked for once (nothing spreads it, so more would overshoot the bone's surface). Packing's
# polish, which iterates to the end, does not over-relax (the packer's PACK_RELAX; docs/CONTACT.md).
CONTACT_RELAX = (1.6, 2.0, 2.0)
# [1 2 1]/4 smoothing rounds of the rings' modes along the muscle (no creases). The modes of the
# muscles' pushes are pinned at the poles (the attachments, where muscles meet at a shared
# origin, do not move); those of the bones' pushes are smoothed with free ends, so the rings
# next to an attachment keep their own push out of the bone (the pole itself stays): pinned,
# a tendon's end ring would never leave the bone it attaches to.
CONTACT_SMOOTH_PASSES = 4
# Bones' signed distance fields: grid step and padding around the mesh (m). Trilinear on a
# 3 mm grid reads a convex bone's distance too large (a convex function's chords lie above
# it), by up to about 1 mm at the vertices contact leaves inside a bone. A 2 mm grid halves
# that, for 3.4x the memory, and barely changes what contact leaves inside (docs/CONTACT.md).
CONTACT_SDF_STEP = 0.003
CONTACT_SDF_PAD = 0.02
# Shares of an overlap: 0.5 each for equal yields, +CONTACT_SHARE_PER_LAYER per layer of
# yield difference for the deeper muscle, at most CONTACT_SHARE_MAX.
CONTACT_SHARE_PER_LAYER = 0.3
CONTACT_SHARE_MAX = 0.8
# A bone's field covers the muscles' rest meshes (in that bone's frame) grown by this (m):
# far enough for a pose to bring a muscle near its neighbour bones (a muscle that moves further
# from a bone than this between rest and pose is not compared with it), small enough not to
# sample a whole floor or torso.
CONTACT_REACH = 0.1
# One yield layer (m of distance from the bone surface): a muscle whose middle lies
# 1 cm nearer a bone gives way 0.3 more of an overlap (tol.CONTACT_SHARE_PER_LAYER).
CONTACT_LAYER = 0.01
# The box a bone's field covers is rounded out to whole steps of this (m), so that editing a
# muscle a little keeps the same field (and its cache entry).
CONTACT_CLIP_STEP = 0.05
# A point is pushed out of a neighbour along the line from the neighbour's axis to the point's
# own section centre, plus this many neighbour radii of the point's radial direction: the
# direction stays defined (and continuous) where the two axes meet.
CONTACT_RADIAL_BLEND = 0.25
# A point moves at most this far (m) in one contact pass: a deep overlap is cleared over
# several passes instead of in one jump that overshoots into a third muscle.
CONTACT_MAX_STEP = 0.004
# A point nearer a neighbour's axis than CONTACT_DEEP_FADE[1] of its radius is pushed less,
# not at all nearer than CONTACT_DEEP_FADE[0] (smoothstep between): muscles on one line of
# action have no side to push each other to, and pushing them anyway piles them up.
CONTACT_DEEP_FADE = (0.15, 0.5)
# Likewise for the distance between the point's own ring centre and the neighbour's axis, in
# the neighbour's radii: where the axes (nearly) meet, the push's direction turns fast.
CONTACT_AXES_FADE = (0.1, 0.4)
# The deep fade reads the larger of the point's distance from the neighbour's axis and this
# much of its ring centre's: a ring that crosses a neighbour off its axis is pushed out even
# where its points pass near that axis (the push's direction is the centres', defined there;
# the point's own radial part of it still fades), as the sartorius crossing the adductor
# brevis. 1.0 makes the walk as imported step over 1.5x (a pop); 0.75 stays under it.
CONTACT_DEEP_FADE_CENTRES = 0.75
# A thin muscle inside a thick one (its ring's radius below CONTACT_THIN[1] of the neighbour's
# radius, fully from CONTACT_THIN[0], smoothstep between) also makes the thick one give way:
# none of the thick one's points is inside the thin one, so its own samples never ask it to.
CONTACT_THIN = (0.25, 0.5)
# The pushes are sampled at A / CONTACT_SAMPLE_COLUMNS evenly spaced points (12 of 24) of every
# CONTACT_SAMPLE_RINGS-th ring; each sampled ring's displacement modes are fitted to them.
# Sparser (8 points of every second ring) aliases: the pushes turn between frames near shared
# attachments (pops); all 24 points of every ring gain nothing for 1.5x the cost.
CONTACT_SAMPLE_COLUMNS = 2
CONTACT_SAMPLE_RINGS = 1

# Packing (axdf_cli/model/pack.py): rounds of territory and fit, pixels across a ring's
# square, the square's half side over the ring's radius, the gap left inside a territory's
# boundary (m), the fit's pull towards the current outline, the largest envelope scale.
PACK_ITERATIONS = 20
PACK_PIXELS = 40
PACK_GROW = 1.6
PACK_MARGIN = 0.001
PACK_PULL = 0.02
# the fit's smoothness along the muscle (second differences over sections, relative to the data)
PACK_SMOOTH = 0.2
PACK_SCALE_MAX = 3.0
# sections of a packed muscle (evenly between its first and last), the volume step's gain
PACK_SECTIONS = 16
PACK_GAIN = 0.5
PACK_STEP = 1.06
# rounds of drawing in the targets of fitted vertices outside their territory, by this factor
PACK_FIT_ROUNDS = 12
PACK_DRAW_IN = 0.8
# Polish (step 5): rounds of the frame's contact resolved at the rest pose with this many passes
# (a one-off, so no pops to avoid: as many as clear it), the sections fitted to it each round.
# Each round clears most of what the one before left; three leave a few hundredths of a per
# cent of the rest vertices inside another muscle, and fewer passes a round leave more.
PACK_POLISH_ROUNDS = 3
PACK_POLISH_PASSES = 24
# `axdf pack --pose`: the polish also runs at this many of the pose's frames (evenly spaced;
# every frame of a shorter pose), and fits the mean of its displacements there and at rest.
PACK_POSE_FRAMES = 16
# A packed section's control points keep to their rays from its centre (star-shaped sections,
# pack.Fit), each at least this share of the section's original mean radius from it.
PACK_RAY_MIN = 0.15
# `axdf pack` holds about PACK_BYTES_PER_VERTEX of memory per muscle vertex at once (distance
# queries, territories, fits); a pack of more than PACK_MAX_VERTICES vertices (about 6.4 GiB)
# is refused before any work. gait2392's 92 muscles at the default 40x24 hold 88,320; a single
# muscle at the spec's limit (1000x1000) would need about 27 GB.
PACK_BYTES_PER_VERTEX = 27 * 1024
PACK_MAX_VERTICES = 250_000

# Jiggle's bound (axdf_cli/model/jiggle.py, `bounded`): the written offset of an axis control
# point from where the bones put it is at most JIGGLE_BOUND of the muscle's axis length at
# that frame (its control polygon's), reached smoothly: unchanged up to JIGGLE_BOUND_KNEE of
# the bound, then a tanh shoulder (the same value, slope and curvature at the knee: no kink).
# Soft tissue sways centimetres on muscles tens of centimetres long; the shipped gait2392 walk
# moves axes by at most 3.5% of their length and the hand-keyed hop's dead-stop landing, the
# hardest shipped motion, by 16.8% (vastus medialis), below the knee (18.75%), so neither
# changes. What it stops is a motion too fast for its frame rate (the walk played 10x fast
# moved axes by 270% of their length): an offset of a quarter of the length in the middle
# of a two-segment axis lengthens it by sqrt(1 + 4 * 0.25^2) - 1 = 12%.
JIGGLE_BOUND = 0.25
JIGGLE_BOUND_KNEE = 0.75
# Jiggle's memory (axdf_cli/pipeline/jiggle_stage.py): the pose's timeline is cut into
# epochs (axdf_cli/pipeline/evaluate.py, TIME_EPOCH_BLOCKS); a muscle's oscillators for an
# epoch start from the pre-roll steady state as many frames before it as make any start
# state's difference decay to JIGGLE_WARMUP_EPS of itself (model/jiggle.py, warmup_frames),
# so a frame costs at most an epoch and a warm-up, not the whole pose before it. At 1e-9 the
# jump where two epochs meet is below a nanometre for a 1 m offset (float32 positions near
# 1 m resolve 60 nm): no pop. A walk's slowest shipped muscle (8 Hz, damping 0.2) needs 2.1 s
# of warm-up; an undamped muscle integrates from the pose's first frame.
JIGGLE_WARMUP_EPS = 1e-9

# ---------------------------------------------------------------- importers (hostile inputs)
# A MuJoCo joint coupling is a polynomial of degree at most 4 (polycoef); a chain of couplings
# composes them, so the degree multiplies along the chain (4^n). Chains whose composed degree
# exceeds this are refused at the coupling that passes it: three quartics in a chain (64) are
# more than any published model uses, and each further link would multiply the work and the
# coefficients' size by 4 (a chain of 9-10 quartics overflows to NaN, 11 or more never ends).
COUPLING_MAX_DEGREE = 64
# An imported muscle whose path is shorter than this at rest (metres) holds no belly: a tendon
# through one site twice, or through coincident sites. It is skipped, with a warning.
IMPORT_MIN_PATH_LENGTH = 1e-4
# Sizes of an imported muscle beyond these (metres) are warned: no human or animal muscle has
# a path over 5 m (a giraffe's neck muscles are about 2-3 m) or a belly over 1 m across. Such
# sizes come from a model in other units (millimetres read as metres) or a typing slip.
IMPORT_PLAUSIBLE_PATH = 5.0
IMPORT_PLAUSIBLE_BELLY = 1.0
# An imported bone mesh less than this across (metres) once scaled and placed has collapsed to
# a point (a scale of 0, or one that underflows float32): refused. The smallest bones modelled
# (ossicles, sesamoids) are millimetres across.
IMPORT_MIN_MESH_SIZE = 1e-6
# Bytes one array of an .npz motion (a qpos motion, joint positions) may take once read: the
# limit is checked from the array's header before any data is decompressed, so a small file
# that claims a huge array costs nothing (a compressed archive can expand a thousandfold).
NPZ_MAX_ARRAY_BYTES = 256 * 1024 * 1024

# Automatic framing (axdf_cli/render/framing.py): the camera frames the subject at no more than
# FRAMING_SAMPLE frames of the pose, spread evenly (every frame of a shorter pose), so one frame
# of a very long pose costs a bounded amount; at 30 fps 600 samples of a 20 s take lie one frame
# apart, and FRAMING_PAD (model/pose.py) covers what a limb moves between samples of a longer one.
FRAMING_SAMPLE = 600
# The muscles alone are framed (a close-up) when their extent over the pose is under this share
# of the whole subject's (bones and joints): a deltoid on a whole arm and trunk fills the image
# instead of showing as a blob; a body's worth of muscles frames the body they are shown on.
FRAMING_CLOSEUP = 0.5
# A ground plate (a mesh on a root without DOFs) is drawn under the subject at least this many
# metres beyond its footprint each way, or this share of the subject's height if that is more.
GROUND_MARGIN = 0.3
GROUND_MARGIN_FRACTION = 0.25
# Only a flat mesh is a ground plate: its height at most this share of its width (gait2392's
# ground is 2 cm thick and metres wide); a fixed prop on such a root (a rig's ball) stays put.
GROUND_FLAT = 0.1

# `axdf skin` (axdf_cli/tools/skin.py, docs/SKIN.md). The skeleton's stature is estimated from
# its joints with the segment fractions of body height H of Drillis & Contini (1966), as Winter
# tabulates them (Biomechanics and Motor Control of Human Movement, 4th ed., 2009, Fig. 4.1):
# thigh 0.245 H + shank 0.246 H; sole to ankle 0.039 H; shoulder joint to head top 1 - 0.818 H.
SKIN_LEG_FRACTION = 0.491
SKIN_ANKLE_FRACTION = 0.039
SKIN_ABOVE_SHOULDER_FRACTION = 0.182
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
# The muscle-under-skin pass (render/under.py) names a muscle only within this distance of the
# skin (metres): subcutaneous fat is at most a few centimetres where muscles lie under it
# (Störchle 2018's thickest site, the lower abdomen, about 4 cm at BMI 30); farther, as over the
# head or gait2392's arms, no muscle lies beneath and the pixel reads 0.
SKIN_UNDER_MAX_DEPTH = 0.06
# The skin stage of `axdf run --skin` (axdf_cli/pipeline/skin_stage.py, docs/SKIN.md). Muscle and
# bone vertices within SKIN_REACH metres of the rest skin are its candidates (deeper ones stay
# under it: a walk slides muscles a few cm under the skin at most); each is measured, every
# frame, against the nearest of its SKIN_CANDIDATES nearest rest skin vertices (their spacing
# is ~1-2 cm, so 8 cover the ~3 cm a muscle slides under the skin at a joint).
SKIN_REACH = 0.05
SKIN_CANDIDATES = 8
# A candidate is kept at least its local fat thickness under the skin, or as deep as the rest
# skin holds it where that is shallower (the fitted rest skin clears the muscles by
# SKIN_PUSH_CLEARANCE only; asking for the full fat there would inflate it at rest).
# A candidate more than SKIN_MAX_HEIGHT metres above a skin vertex (along its normal) pushes it
# not at all: measured on the walk, the muscle vertices truly outside the skinned mesh (winding
# number) lie at most 28 mm above it, while those 3-9 cm "above" lie in the crease between the
# thighs, inside the body, the vertex on the other leg.
SKIN_MAX_HEIGHT = 0.035
# Above SKIN_SOFT_HEIGHT a candidate's push fades linearly to nothing at SKIN_MAX_HEIGHT: a point
# rising through the limit would otherwise drop a push of ~35 mm between two frames (a pop).
SKIN_SOFT_HEIGHT = 0.03
# A point pushes a skin vertex in full while it lies within SKIN_SPREAD_IN times the vertex's
# longest edge of it across the vertex's normal (the triangles around the vertex), less and
# less out to SKIN_SPREAD_OUT times that (a smoothstep), and not at all beyond: a point sliding
# under the skin hands its push on without a jump. Measured at the CMU walk's deepest crouch
# (frames 91..96), muscle vertices outside the skin by the winding number: 0.46% at 1 and 2
# edges, 0.38% at 1.5 and 3, 0.36% at 2 and 4 (beyond that a point's 8 candidates end first).
SKIN_SPREAD_IN = 1.5
SKIN_SPREAD_OUT = 3.0
# A skin's jiggle (its file's `jiggle:`) remembers at most this many seconds of the bones' motion:
# a spring whose ring takes longer to die away to a thousandth is cut there.
SKIN_JIGGLE_MEMORY = 2.0
# Relaxation after the push: passes of neighbour averaging of the offsets, each held at least
# at its push (sticky); about one edge (~1-2 cm) of spread per pass, so a push becomes a smooth
# bulge, not a spike. Each pass also widens the bulges: on the walk 6 passes gain the skin
# +3.1..4.3% of its volume, 3 passes +2.4..3.5%.
SKIN_RELAX_ITERATIONS = 3
# The volume step after the relax holds the skin at its volume as worn at rest (soft tissue is
# incompressible): the excess the pushes and the relax add is taken back from vertices with
# room under them, each in by a common depth of at most SKIN_VOLUME_MAX_SHIFT metres (about the
# thinnest fat, so a region with nothing under it does not cave in), the step's edge next to
# vertices held at their floor tapered over SKIN_VOLUME_TAPER rings; SKIN_VOLUME_ROUNDS
# rounds, each on the moved mesh (the first is a linear estimate).
SKIN_VOLUME_MAX_SHIFT = 0.008
SKIN_VOLUME_TAPER = 2
SKIN_VOLUME_ROUNDS = 2
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
