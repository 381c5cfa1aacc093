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

# The largest frame error (radians) the RMF sampling may leave; tests check RMF_SAMPLES_PER_SPAN
# achieves it.
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
# highest end site lies inside the head and a rest pose may splay the legs (as CMU's
# conversions do); a T-pose whose top end site is the vertex (span = stature) then reads a
# little tall, still inside the band for ordinary statures.
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
# (far below motion capture's millimetre), or after IK_MAX_EVALUATIONS (far more than a frame
# started from the one before needs).
IK_FTOL = 1e-10
IK_XTOL = 1e-10
IK_GTOL = 1e-10
IK_MAX_EVALUATIONS = 200
# The pull towards the previous frame (a retarget map's `smooth:` default), as residual metres
# per degree of a rotation: a 10 degree change between frames costs as much as 1 cm of joint
# centre error. Where the points decide a coordinate it is negligible (a 0.4 m lever moves its
# end 7 mm per degree, ~50 times the pull's weight in the cost: a lag of ~2% of a frame's
# change); it decides what the points barely tell: a hip's rotation about a nearly straight
# leg, a toe's flexion on a 5 cm lever (a much weaker pull lets noisy toe joints flick the
# toes between frames). Translations: 0.01 m per metre (the root is seen directly).
IK_SMOOTH_ROTATION = 1e-3
IK_SMOOTH_TRANSLATION = 1e-2
# A free coordinate within this share of its range's width of an end is reported as held there.
IK_AT_BOUND = 1e-6

# A motion column of a coupled coordinate (a CoordinateCouplerConstraint's dependent) is
# not read: the skeleton computes it. When it strays from the coupler's function of its
# leader's column by more than this (OpenSim units, rad or m) the import warns. OpenSim's IK
# satisfies the constraint to its assembly accuracy and a motion file prints 8 decimals;
# 1e-5 rad (6e-4 deg, 10 µm) is far above both and far below anything visible.
COUPLED_COLUMN_ATOL = 1e-5

# Axis control points of imported path muscles (axdf import osim|mjcf; importers/emit.py
# axis_points_for). The axis is a quadratic B-spline fitted to the wrapped path, and it cuts
# the path's corners: a hamstring's insertion hook at deep knee flexion, finger flexors that
# fold sharply over a few millimetres (MyoSuite's hands). Each muscle keeps the default count
# (8 + 4 per interior point and surface, at most 48) unless its axis length differs from the
# wrapped path's by more than AXIS_SHORTFALL_MAX in some measured pose; then it gets the first
# count that stays within: steps of AXIS_POINTS_STEP up to AXIS_POINTS_FINE_MAX (a bend needs
# a few more points near it, and every point costs evaluation time in every frame), then of
# AXIS_POINTS_COARSE_STEP up to AXIS_POINTS_MAX (the muscle spec's limit: 128 points put a knot
# every 0.8% of the path, ~2 mm of a finger flexor), or the best of them.
# AXIS_SHORTFALL_MAX is half of the 1% within which every imported muscle must match its
# simulator's own length (OpenSim's getLength, MuJoCo's ten_length): the rest is room for the
# wrapping's own tolerances and for poses the importer did not measure.
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
# kept, press it into the next layer and follow the neighbours' motion more: two passes are
# the most that keep every vertex's step between frames near the no-contact one (no pops; the
# contact rows of `make bench` measure it, docs/BENCH.md).
CONTACT_ITERATIONS = 2
# Over-relaxation of a pass's pushes: the muscles' pushes, the bones' and the thick muscles'
# giving way (to a thin muscle or a pole inside them) are asked for this many times over. A
# pass delivers only part of what its samples ask for at the deepest points (the rings' five
# modes and the smoothing along the muscle spread a local push, and the volume's re-solve
# gives some back), so two passes without it leave overlap they could clear; asked for much
# more, the muscles' pushes overshoot between frames (pops). A pole's own push out of a bone is
# asked for once (nothing spreads it, so more would overshoot the bone's surface). Packing's
# polish, which iterates to the end, does not over-relax (the packer's PACK_RELAX; docs/CONTACT.md).
CONTACT_RELAX = (1.6, 2.0, 2.0)
# [1 2 1]/4 smoothing rounds of the rings' modes along the muscle (no creases). The modes of the
# muscles' pushes are pinned at the poles (the attachments, where muscles meet at a shared
# origin, do not move); those of the bones' pushes are smoothed with free ends, so the rings
# next to an attachment keep their own push out of the bone (the pole itself stays): pinned,
# a tendon's end ring would never leave the bone it attaches to.
CONTACT_SMOOTH_PASSES = 4
# Bones' signed distance fields: grid step and padding around the mesh (m). Trilinear
# interpolation reads a convex bone's distance too large (a convex function's chords lie above
# it), by a fraction of the step; a finer grid costs memory as the cube of the step and barely
# changes what contact leaves inside a bone (docs/CONTACT.md).
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
# brevis. Less than 1: at the centres' full distance a crossing ring's step between frames grows
# into a pop.
CONTACT_DEEP_FADE_CENTRES = 0.75
# A thin muscle inside a thick one (its ring's radius below CONTACT_THIN[1] of the neighbour's
# radius, fully from CONTACT_THIN[0], smoothstep between) also makes the thick one give way:
# none of the thick one's points is inside the thin one, so its own samples never ask it to.
CONTACT_THIN = (0.25, 0.5)
# The pushes are sampled at A / CONTACT_SAMPLE_COLUMNS evenly spaced points (12 of 24) of every
# CONTACT_SAMPLE_RINGS-th ring; each sampled ring's displacement modes are fitted to them.
# Sparser sampling aliases: the pushes turn between frames near shared attachments (pops);
# denser sampling costs more and gains nothing.
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
# Each round clears most of what the one before left; fewer passes a round leave more.
PACK_POLISH_ROUNDS = 3
PACK_POLISH_PASSES = 24
# A packed section's control points keep to their rays from its centre (star-shaped sections,
# pack.Fit), each at least this share of the section's original mean radius from it.
PACK_RAY_MIN = 0.15

# Jiggle's bound (axdf_cli/model/jiggle.py, `bounded`): the written offset of an axis control
# point from where the bones put it is at most JIGGLE_BOUND of the muscle's axis length at
# that frame (its control polygon's), reached smoothly: unchanged up to JIGGLE_BOUND_KNEE of
# the bound, then a tanh shoulder (the same value, slope and curvature at the knee: no kink).
# Soft tissue sways centimetres on muscles tens of centimetres long: the knee lies above what
# the shipped motions reach, the hardest (a hop's dead-stop landing) included, so they are
# unchanged (docs/BENCH.md, jiggle). What it stops is a motion too fast for its frame rate,
# whose offsets grow past the axis's own length: an offset of a quarter of the length in the
# middle of a two-segment axis lengthens it by sqrt(1 + 4 * 0.25^2) - 1 = 12%.
JIGGLE_BOUND = 0.25
JIGGLE_BOUND_KNEE = 0.75
# Jiggle's memory (axdf_cli/pipeline/jiggle_stage.py): the pose's timeline is cut into
# epochs (axdf_cli/pipeline/evaluate.py, TIME_EPOCH_BLOCKS); a muscle's oscillators for an
# epoch start from the pre-roll steady state as many frames before it as make any start
# state's difference decay to JIGGLE_WARMUP_EPS of itself (model/jiggle.py, warmup_frames),
# so a frame costs at most an epoch and a warm-up, not the whole pose before it. At 1e-9 the
# jump where two epochs meet is below a nanometre for a 1 m offset (float32 positions near
# 1 m resolve 60 nm): no pop. The slower and less damped a muscle, the longer its warm-up; an
# undamped muscle integrates from the pose's first frame.
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
# of the whole subject (bones and joints): a deltoid on a whole arm and trunk fills the image
# instead of showing as a blob; a body's worth of muscles frames the body they are shown on.
FRAMING_CLOSEUP = 0.5
# A ground plate (a mesh on a root without DOFs) is drawn under the subject at least this many
# metres beyond its footprint each way, or this share of the subject's height if that is more.
GROUND_MARGIN = 0.3
GROUND_MARGIN_FRACTION = 0.25
# Only a flat mesh is a ground plate: its height at most this share of its width (gait2392's
# ground is 2 cm thick and metres wide); a fixed prop on such a root (a rig's ball) stays put.
GROUND_FLAT = 0.1

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
# not at all: it lies above the muscle vertices truly outside the skinned mesh (winding number)
# and below the points that only seem "above" a skin vertex, in the crease between the thighs,
# inside the body, the vertex on the other leg.
SKIN_MAX_HEIGHT = 0.035
# Above SKIN_SOFT_HEIGHT a candidate's push fades linearly to nothing at SKIN_MAX_HEIGHT: a point
# rising through the limit would otherwise drop a push of ~35 mm between two frames (a pop).
SKIN_SOFT_HEIGHT = 0.03
# A skin grown outward over muscle and bone points that lie outside it (axdf skin --push, and the
# skin stage for a skin worn over muscles it was not fitted to; axdf_cli/geometry/grow.py): rounds
# at most, the clearance each point is given (metres: the skin ends at least this far outside it),
# and passes of neighbour averaging that spread each push over the skin around it (no spikes).
SKIN_PUSH_ROUNDS = 8
SKIN_PUSH_CLEARANCE = 0.002
SKIN_PUSH_SMOOTHING = 4
# A skin worn over muscles it was not fitted to: more than this share of the muscle vertices (or
# of the worn bones' points) outside it at rest is said on stderr, with the command that refits
# it (the bounds a fitted skin holds: docs/SKIN.md).
SKIN_FOREIGN_MUSCLE_SHARE = 0.005
SKIN_FOREIGN_BONE_SHARE = 0.001
# A point pushes a skin vertex in full while it lies within SKIN_SPREAD_IN times the vertex's
# longest edge of it across the vertex's normal (the triangles around the vertex), less and
# less out to SKIN_SPREAD_OUT times that (a smoothstep), and not at all beyond: a point sliding
# under the skin hands its push on without a jump. Wider spreads leave fewer muscle vertices
# outside the skin, less and less so, until a point's SKIN_CANDIDATES end first.
SKIN_SPREAD_IN = 1.5
SKIN_SPREAD_OUT = 3.0
# A skin's jiggle (its file's `jiggle:`) remembers at most this many seconds of the bones' motion:
# a spring whose ring takes longer to die away to a thousandth is cut there.
SKIN_JIGGLE_MEMORY = 2.0
# ...and samples that memory at most SKIN_JIGGLE_TAPS times (at the pose's frames while they
# are fewer, else evenly between them: the pose is a function of time), so the work and the
# memory follow the output, not the pose's fps (every frame would ask fps x memory samples of
# the skeleton). The lightest damping allowed (0.05) rings out to a thousandth in 22 periods
# (ln 1000 / (2 pi 0.05)), so 512 samples keep at least 23 per period of the ring at any
# frequency (tests/test_skin_unit.py holds the lag to the full filter's).
SKIN_JIGGLE_TAPS = 512
# Relaxation after the push: passes of neighbour averaging of the offsets, each held at least
# at its push (sticky); about one edge (~1-2 cm) of spread per pass, so a push becomes a smooth
# bulge, not a spike. Each pass also widens the bulges and adds to the skin's volume, which
# the volume step below takes back: a few passes are enough for smooth bulges.
SKIN_RELAX_ITERATIONS = 3
# Delta mush (the skin file's skinning: delta_mush): the skinned mesh is smoothed by
# SKIN_MUSH_ITERATIONS passes of uniform Laplacian smoothing of SKIN_MUSH_STEP before its rest
# detail is put back. MakeHuman's edges are 1-3 cm: 10 passes of 0.5 spread over a few cm,
# the width of a crease, and leave a limb's cross-section to the deltas.
SKIN_MUSH_ITERATIONS = 10
SKIN_MUSH_STEP = 0.5
# The volume step after the relax holds the skin at its volume as worn at rest (soft tissue is
# incompressible): the excess the pushes and the relax add is taken back from vertices with
# room under them, each in by a common depth of at most SKIN_VOLUME_MAX_SHIFT metres (about the
# thinnest fat, so a region with nothing under it does not cave in), the step's edge next to
# vertices held at their floor tapered over SKIN_VOLUME_TAPER rings; SKIN_VOLUME_ROUNDS
# rounds, each on the moved mesh (the first is a linear estimate).
SKIN_VOLUME_MAX_SHIFT = 0.008
SKIN_VOLUME_TAPER = 2
SKIN_VOLUME_ROUNDS = 2
# A skin file's rest mesh (axdf_cli/specs/skin.py) is a body: its largest extent (bounding box)
# at least SKIN_MIN_EXTENT metres (a hand-sized figure; a mesh collapsed to a point has 0) and
# at most SKIN_MAX_EXTENT (a vertex at 1e30 makes it astronomic), and its volume at least
# SKIN_MIN_FILL of its extent cubed (a person fills ~1.3% of the cube of its height; a mesh
# folded flat, closed but two-sided, has none).
SKIN_MIN_EXTENT = 0.05
SKIN_MAX_EXTENT = 10.0
SKIN_MIN_FILL = 1e-3
# A skin's weights name at most SKIN_MAX_BONES bones (more than any skeleton axdf reads: the
# densest, myobody, has under 100) and names of at most SKIN_MAX_NAME characters: checked from
# the NPZ's headers before anything is read (112 kB of NPZ can name 3 million bones, whose
# dense weights would take hundreds of GB).
SKIN_MAX_BONES = 1024
# A skin's fat map holds thicknesses of at most SKIN_MAX_FAT metres (the regions' fat_mm are at
# most 100 mm; a vertex's thickness widens the reach of every muscle and bone point it holds)
SKIN_MAX_FAT = 0.1
SKIN_MAX_NAME = 256
# A skin is worn only on a skeleton whose fitted segments (docs/SKIN.md: thigh, shank, foot,
# trunk, arms, the skin file's `segments:`) are within SKIN_SEGMENT_TOLERANCE of the lengths it
# was fitted to (or, for a skin file without `segments:`, whose estimated stature is): 5% of a
# 40 cm thigh moves the knee's skin 2 cm, more than the fat over it.
SKIN_SEGMENT_TOLERANCE = 0.05
# A skin file without `segments:` (written before axdf skin recorded them, as skins/gait2392):
# the skeleton's joints the skin wears lie inside its rest mesh, or at most SKIN_FIT_OUTSIDE
# metres outside it: more than a skin fitted to the skeleton itself leaves out (its heels and
# head's origin, by millimetres), far less than a skeleton of other proportions puts out (a
# longer shank's feet, by decimetres).
SKIN_FIT_OUTSIDE = 0.03
