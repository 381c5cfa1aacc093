# axdf: two commands on a fresh machine.
#   make demo   set up (.venv with axdf and the packages it runs on, Mesa EGL if missing), compile
#               every command's kernels (make warm) and run the demo jobs into out/ (no test tools)
#   make test   set up, add the test tools (pytest, hypothesis, opensim, mujoco, ray, ...) and run
#               the whole test suite (CI calls this through .ci/run); also creates .venv-blender
#               (bpy) for the Blender check
#   make test-fast  the unit tier only (TIER="integration" etc. picks another: unit, integration,
#               judges, hostile; see tests/conftest.py TIERS)
#   make dataset  set up and build a small gait2392 data set into out/gait2392_small
#   make bench  set up, print the benchmark tables and write them to docs/BENCH.md (BENCH_ARGS="--quick", "--long", "--only NAME[,NAME]": those sections only, the page keeps the others)
PY     ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed
# the test tools on top (the [test] extra): pytest, hypothesis, opensim, mujoco, myo-sim, ray, ...
TEST_STAMP := $(VENV)/.installed-test
# Blender as a Python module (bpy) for tests/test_blender.py, in its own environment: bpy 5
# needs numpy<2 and axdf numpy 2. ~1.5 GB, about a minute; a failed install is a warning and
# the test skips, saying why.
BLENDER_VENV  := .venv-blender
BLENDER_STAMP := $(BLENDER_VENV)/.installed
BLENDER_PKGS  ?= bpy>=4.2 usd-core>=24.11
# at the versions the check last passed with (constraints-blender.txt); the ranges above when
# those cannot be installed
BLENDER_CONSTRAINTS := constraints-blender.txt
DEMO   ?= poses/jobs/demo.yaml

# OpenSim data for `make import` (opensim-models; see README "Data credits").
DATA   ?= ../shared/data
OSIM   := $(DATA)/opensim
BVH    := $(DATA)/bvh/cmu_131_01_walk_scaled.bvh
# MyoSuite models (the installed myo-sim package) written as MJCF files, and their motions.
MYO    := out/myo-sim
MJCF_MESHES := --max-faces 2000 --mesh-edge 0.004

# The golden check renders through the cameras blessed with the golden files (docs/COMPARE.md):
# the automatic camera frames the muscles, so without it a change to one muscle would move
# the camera and fail every image.
GOLDEN_CAMERA ?= $(if $(wildcard tests/golden/camera.json),--camera tests/golden/camera.json)

.PHONY: all setup setup-test sysdeps warm demo dataset test test-fast bench golden clean import import-mjcf pack pack-check lock blender skin atlas atlas-myoarm atlas-myobody

all: demo

setup: $(STAMP)

setup-test: $(TEST_STAMP)

# Mesa's EGL (llvmpipe) for headless rendering without a GPU. Installed with apt-get
# only when the libraries are missing and we are root; otherwise print the command.
sysdeps:
	@if ldconfig -p 2>/dev/null | grep -q 'libEGL.so.1' && ldconfig -p 2>/dev/null | grep -q 'libEGL_mesa.so.0' \
	   && ls /usr/lib/*/dri/swrast_dri.so >/dev/null 2>&1; then :; \
	elif [ "$$(id -u)" = "0" ] && command -v apt-get >/dev/null; then \
	  echo "installing Mesa EGL (libegl1 libegl-mesa0 libgl1-mesa-dri libgles2)"; \
	  apt-get update -q && DEBIAN_FRONTEND=noninteractive apt-get install -y -q libegl1 libegl-mesa0 libgl1-mesa-dri libgles2; \
	else \
	  echo "warning: Mesa EGL missing; install it with: sudo apt-get install -y libegl1 libegl-mesa0 libgl1-mesa-dri libgles2" >&2; \
	fi

# The packages come at the versions in constraints.txt (the environment the shipped
# muscles/gait2392_packed was made in: packing amplifies the last digits of numba's, numpy's
# and libigl's arithmetic, so another release makes another library). Where those versions
# cannot be installed (another Python), the newest that pyproject.toml allows, with a warning.
CONSTRAINTS := constraints.txt
PIP_PINNED   = $(BIN)/python -m pip install -q -c $(CONSTRAINTS)

$(STAMP): pyproject.toml $(CONSTRAINTS)
	@echo "set-up 1/3: Mesa's EGL libraries (headless rendering), when missing"
	@$(MAKE) --no-print-directory sysdeps
	@echo "set-up 2/3: a virtual environment in $(VENV)"
	@$(PY) -m venv $(VENV)
	@$(BIN)/python -m pip install -q --upgrade pip
	@echo "set-up 3/3: axdf and its packages into $(VENV) (numpy, scipy, numba, moderngl, OpenEXR, usd-core, pandas, ...; about a minute)"
	@$(PIP_PINNED) -e '.[recipes]' || { echo "warning: the versions in $(CONSTRAINTS) could not be installed;" \
	  "installing the newest that pyproject.toml allows (make pack-check may then differ)" >&2; \
	  $(BIN)/python -m pip install -q -e '.[recipes]'; }
	@touch $@
	@echo "set-up done: $(BIN)/axdf"

# The test tools (the [test] extra) for make test, test-fast, import-mjcf and lock; never for the demo.
$(TEST_STAMP): $(STAMP)
	@echo "set-up: the test tools into $(VENV) (pytest, hypothesis, opensim, mujoco, myo-sim, ray, ...; a few minutes)"
	@$(PIP_PINNED) -e '.[test]' || { echo "warning: the versions in $(CONSTRAINTS) could not be installed;" \
	  "installing the newest that pyproject.toml allows" >&2; \
	  $(BIN)/python -m pip install -q -e '.[test]'; }
	@touch $@

blender: $(BLENDER_STAMP)

$(BLENDER_STAMP): $(BLENDER_CONSTRAINTS)
	@if $(PY) -m venv $(BLENDER_VENV) && $(BLENDER_VENV)/bin/python -m pip install -q --upgrade pip \
	   && { $(BLENDER_VENV)/bin/python -m pip install -q -c $(BLENDER_CONSTRAINTS) $(foreach p,$(BLENDER_PKGS),'$(p)') \
	        || { echo "warning: the versions in $(BLENDER_CONSTRAINTS) could not be installed; the newest allowed" >&2; \
	             $(BLENDER_VENV)/bin/python -m pip install -q $(foreach p,$(BLENDER_PKGS),'$(p)'); }; } \
	   && $(BLENDER_VENV)/bin/python -c "import bpy"; then touch $@; \
	else echo "warning: could not install bpy into $(BLENDER_VENV); tests/test_blender.py will skip" >&2; fi

DEMO_JOBS := $(DEMO):out/demo poses/jobs/gait2392_walk.yaml:out/gait2392_walk \
  poses/jobs/paper_deltoid_arm26.yaml:out/paper_deltoid_arm26 \
  poses/jobs/paper_gastrocnemius_gait2392.yaml:out/paper_gastrocnemius_gait2392 poses/jobs/cmu_walk.yaml:out/cmu_walk \
  poses/jobs/gait2392_cmu_walk.yaml:out/gait2392_cmu_walk

# Every command's numba kernels compiled into the kernel cache, with progress (scripts/warm_kernels.py
# runs run, fit, skin and dataset build once on tiny inputs): after it no first command compiles.
warm: $(STAMP)
	@echo "warm: compiling every command's kernels once (run, fit, skin, dataset; minutes on a cold cache, seconds after)"
	@$(BIN)/python scripts/warm_kernels.py

demo: $(STAMP) warm
	@n=0; for jo in $(DEMO_JOBS); do n=$$((n + 1)); job=$${jo%%:*}; out=$${jo#*:}; \
	  echo "demo $$n/6: axdf run $$job --out $$out (meshes, then rendered frames)"; \
	  AXDF_LOG_PROGRESS=20 $(BIN)/axdf run $$job --out $$out --overwrite || exit $$?; done
	@echo "demo results in out/: demo, gait2392_walk, paper_deltoid_arm26, paper_gastrocnemius_gait2392, cmu_walk, gait2392_cmu_walk"
	@echo "  each with meshes/, frames/ (PNG + EXR), camera.json, stats.csv, bones.csv, manifest.json"

# A small data set: gait2392's 92 muscles (see poses/datasets/gait2392_small.yaml).
dataset: $(STAMP)
	@echo "dataset: axdf dataset build poses/datasets/gait2392_small.yaml --out out/gait2392_small --jobs 2"
	AXDF_LOG_PROGRESS=20 $(BIN)/axdf dataset build poses/datasets/gait2392_small.yaml --out out/gait2392_small --overwrite --jobs 2
	@echo "data set in out/gait2392_small: index.parquet, dataset.json, seq_*/ (views/, labels.npz, amodal.json, meshes/)"

test: $(TEST_STAMP) $(BLENDER_STAMP)
	$(BIN)/python -m pytest -q tests
	@echo "golden check: a fresh run of tests/golden_job.yaml, through the golden's own cameras, against tests/golden"
	$(BIN)/axdf run tests/golden_job.yaml --out out/golden-check --overwrite --quiet $(GOLDEN_CAMERA)
	$(BIN)/axdf compare out/golden-check tests/golden --junit out/golden-junit.xml --report out/golden-report.json

# One tier of the suite, for development: the unit tier by default (about a minute once the
# kernels are compiled; the first run compiles them, and says so).
TIER ?= unit
test-fast: $(TEST_STAMP)
	$(BIN)/python -m pytest -q -m "$(TIER)" tests

# Re-bless our own golden files from the current code, printing what changed. The golden's
# cameras stay as they were blessed (a changed muscle changes only its own files); to frame
# the golden job afresh: make golden GOLDEN_CAMERA=
golden: $(STAMP)
	$(BIN)/axdf run tests/golden_job.yaml --out out/golden-check --overwrite --quiet $(GOLDEN_CAMERA)
	$(BIN)/axdf compare out/golden-check tests/golden --update

bench: $(STAMP)
	$(PIP_PINNED) -e '.[bench]' || $(BIN)/python -m pip install -q -e '.[bench]'
	$(BIN)/python -m benchmarks.bench --markdown docs/BENCH.md $(BENCH_ARGS)

# Regenerate the shipped OpenSim library: muscles/{arm26,gait2392}, poses/skeletons/{arm26,gait2392}.yaml
# (+ meshes/), poses/arm26_flex.yaml, poses/gait2392_walk.yaml. Reports: muscles/*/IMPORT.md.
# And the CMU walk: poses/skeletons/cmu_131_01.yaml and poses/cmu_131_01_walk.yaml (BVH at 30 fps),
# muscles/cmu/ (the demo muscles moved onto it through poses/maps/human_r_to_cmu.yaml; TRANSFER.md).
# And the same take fitted onto gait2392 (poses/maps/cmu_to_gait2392.yaml): poses/retargeted/.
# Each command's --out holds its manifest.json, which lists the files it wrote there and
# outside it (the skeletons, poses and bone meshes): --overwrite replaces only those, and only
# while they are as the import wrote them (axdf_cli/fileio/outputs.py).
import: $(STAMP)
	@if [ ! -f "$(OSIM)/arm26/arm26.osim" ] || [ ! -f "$(OSIM)/gait2392/gait2392_thelen2003muscle.osim" ] \
	   || [ ! -f "$(BVH)" ]; then \
	  echo "make import: the source data is not at DATA=$(DATA)" >&2; \
	  echo "  it needs $(OSIM)/arm26/ (arm26.osim, arm26_Kinematics_q.sto, arm26_controls.sto, Geometry/)," >&2; \
	  echo "  $(OSIM)/gait2392/ (gait2392_thelen2003muscle.osim, subject01_walk1_ik.mot," >&2; \
	  echo "  subject01_walk1_controls.sto, Geometry/) and $(BVH)" >&2; \
	  echo "  where to get them: README.md, 'Regenerating the library'; then: make import DATA=/path/to/data" >&2; \
	  exit 2; fi
	$(BIN)/axdf import osim $(OSIM)/arm26/arm26.osim --name arm26 \
	  --motion $(OSIM)/arm26/arm26_Kinematics_q.sto --controls $(OSIM)/arm26/arm26_controls.sto \
	  --fps 60 --pose-name arm26_flex --palette anatomical --out muscles/arm26 --muscles-out muscles/arm26 \
	  --skeleton-out poses/skeletons/arm26.yaml --pose-out poses/arm26_flex.yaml --overwrite
	$(BIN)/axdf import osim $(OSIM)/gait2392/gait2392_thelen2003muscle.osim --name gait2392 \
	  --motion $(OSIM)/gait2392/subject01_walk1_ik.mot --controls $(OSIM)/gait2392/subject01_walk1_controls.sto \
	  --pose-name gait2392_walk --palette anatomical --out muscles/gait2392 --muscles-out muscles/gait2392 \
	  --skeleton-out poses/skeletons/gait2392.yaml --pose-out poses/gait2392_walk.yaml --overwrite
	$(MAKE) --no-print-directory pack
	$(MAKE) --no-print-directory skin
	$(MAKE) --no-print-directory atlas
	$(BIN)/axdf import bvh $(BVH) --name cmu_131_01 --pose-name cmu_131_01_walk --step 4 \
	  --out poses/imports/cmu_131_01 --skeleton-out poses/skeletons/cmu_131_01.yaml \
	  --pose-out poses/cmu_131_01_walk.yaml --overwrite
	$(BIN)/axdf transfer muscles/demo --from poses/skeletons/human_r.yaml --to poses/skeletons/cmu_131_01.yaml \
	  --map poses/maps/human_r_to_cmu.yaml --out muscles/cmu --overwrite
	$(BIN)/axdf retarget $(BVH) --onto poses/skeletons/gait2392.yaml --map poses/maps/cmu_to_gait2392.yaml --step 4 \
	  --name cmu_131_01_walk_gait2392 --out poses/retargeted/cmu_131_01_walk_gait2392 --overwrite
	$(MAKE) --no-print-directory import-mjcf

# MakeHuman's CC0 body fitted to gait2392 and pushed out over its packed muscles at rest:
# skins/gait2392/ (the skin of poses/jobs/gait2392_walk_skin.yaml; docs/SKIN.md). And the
# whole body's, skins/myobody/, over muscles/myobody_atlas (poses/jobs/myobody_atlas_walk.yaml). Seconds.
skin: $(STAMP)
	$(BIN)/axdf skin --skeleton poses/skeletons/gait2392.yaml --muscles muscles/gait2392_packed --push \
	  --out skins/gait2392 --overwrite
	$(BIN)/axdf skin --skeleton poses/skeletons/myobody.yaml --muscles muscles/myobody_atlas --push \
	  --out skins/myobody --overwrite
	printf '%s\n' "# skins/myobody" "" \
	  "MakeHuman's hm08 body (CC0) fitted to myobody's skeleton by \`axdf skin --push\` and grown over" \
	  "muscles/myobody_atlas, whose arms and shoulders derive from BodyParts3D (© The Database Center for" \
	  "Life Science, CC Attribution-Share Alike 2.1 Japan; Mitsuhashi N. et al., Nucleic Acids Research 37" \
	  "(2009) D782-D785, doi:10.1093/nar/gkn613). The skin's shape follows those muscles, so this folder" \
	  "keeps that licence, CC BY-SA 2.1 JP. Made by \`make skin\`." > skins/myobody/README.md

# gait2392's muscles packed at the rest pose and polished over 16 frames of the walk (axdf pack
# --pose: no overlap, volumes kept, section outlines): muscles/gait2392_packed/ (PACK.md), the
# muscles of poses/jobs/gait2392_{walk,hop,cmu_walk}.yaml. From the shipped muscles/gait2392 and
# poses/gait2392_walk.yaml alone (no DATA needed); about two and a half minutes.
# And arm26's 6 muscles over its elbow flexion (poses/jobs/arm26_flex.yaml): muscles/arm26_packed/.
# PACK_OUT: the folder the packed libraries go in (make pack-check packs into out/pack-check).
PACKS := gait2392:gait2392_walk arm26:arm26_flex
PACK_OUT ?= muscles

pack: $(STAMP)
	@for p in $(PACKS); do lib=$${p%%:*}; pose=$${p#*:}; \
	  echo "axdf pack muscles/$$lib --skeleton poses/skeletons/$$lib.yaml --pose poses/$$pose.yaml --out $(PACK_OUT)/$${lib}_packed"; \
	  $(BIN)/axdf pack muscles/$$lib --skeleton poses/skeletons/$$lib.yaml --pose poses/$$pose.yaml \
	    --out $(PACK_OUT)/$${lib}_packed --overwrite $(PACK_FLAGS) || exit $$?; done

# Whether this install makes the shipped packed libraries again, byte for byte: packs each
# into out/pack-check/ and compares every file (exit 1 and the files that differ when not).
pack-check: $(STAMP)
	@$(MAKE) --no-print-directory pack PACK_OUT=out/pack-check PACK_FLAGS=--quiet
	@for p in $(PACKS); do lib=$${p%%:*}; \
	  if diff -rq out/pack-check/$${lib}_packed muscles/$${lib}_packed; then \
	    echo "pack-check: make pack makes the shipped muscles/$${lib}_packed again, byte for byte"; \
	  else echo "pack-check: this install makes another muscles/$${lib}_packed than the shipped one" \
	    "(files above); compare your packages with $(CONSTRAINTS)" >&2; exit 1; fi; done

# constraints.txt made again from the environment in $(VENV) (after a deliberate upgrade; then
# make pack, and ship the library it makes with the new constraints).
lock: $(TEST_STAMP)
	@{ grep '^#' $(CONSTRAINTS); $(BIN)/python -m pip freeze --exclude-editable; } > $(CONSTRAINTS).new && mv $(CONSTRAINTS).new $(CONSTRAINTS)
	@touch $(STAMP) $(TEST_STAMP)  # the environment is the one the file was made from: no set-up again
	@echo "lock: $(CONSTRAINTS) made from $(VENV)"
	@if [ -x $(BLENDER_VENV)/bin/python ]; then \
	  { grep '^#' $(BLENDER_CONSTRAINTS); $(BLENDER_VENV)/bin/python -m pip freeze; } > $(BLENDER_CONSTRAINTS).new \
	    && mv $(BLENDER_CONSTRAINTS).new $(BLENDER_CONSTRAINTS) && touch $(BLENDER_STAMP) \
	    && echo "lock: $(BLENDER_CONSTRAINTS) made from $(BLENDER_VENV)"; fi

# The MyoSuite library (myo-sim, Apache-2.0): muscles/{myoarm,myobody}, poses/skeletons/{myoarm,myobody}.yaml
# (+ meshes/), poses/myoarm_elbow.yaml (arm26's elbow flexion), poses/myobody_gait.yaml (MyoSuite's gait cycle),
# and the CMU walk fitted onto myobody (poses/maps/cmu_to_myobody.yaml): poses/retargeted/cmu_131_01_walk_myobody/.
# muscles/gait2392_atlas: the Visible Human Female atlas (CC BY 4.0) registered onto gait2392
# and fitted under its names by `axdf atlas` (docs/ATLAS.md; about 10 minutes on two cores).
# ATLAS_OUT keeps the registered meshes and residuals; the library is its muscles/ and report.
ATLAS  ?= $(DATA)/atlas/visible_human_female
ATLAS_SIDES ?= r,l
ATLAS_OUT ?= build/atlas_gait2392
atlas: $(STAMP)
	$(BIN)/axdf atlas $(ATLAS) --onto poses/skeletons/gait2392.yaml --map atlases/gait2392.yaml \
	  --muscles muscles/gait2392 --sides $(ATLAS_SIDES) --out $(ATLAS_OUT) --overwrite
	rm -rf muscles/gait2392_atlas.partial
	cp -r $(ATLAS_OUT)/muscles muscles/gait2392_atlas.partial
	cp $(ATLAS_OUT)/atlas_report.json muscles/gait2392_atlas.partial/
	rm -rf muscles/gait2392_atlas && mv muscles/gait2392_atlas.partial muscles/gait2392_atlas

# muscles/myoarm_atlas: BodyParts3D's upper body (CC BY-SA 2.1 JP: the library stays in its own
# folder under that licence) registered onto myoarm's right arm and fitted under myoarm's names
# (atlases/myoarm.yaml, docs/ATLAS.md; about 4 minutes on two cores).
ATLAS_UPPER ?= $(DATA)/atlas/bodyparts3d_upper
ATLAS_ARM_OUT ?= build/atlas_myoarm
atlas-myoarm: $(STAMP)
	$(BIN)/axdf atlas $(ATLAS_UPPER) --onto poses/skeletons/myoarm.yaml --map atlases/myoarm.yaml \
	  --muscles muscles/myoarm --sides r --out $(ATLAS_ARM_OUT) --overwrite
	rm -rf muscles/myoarm_atlas.partial
	cp -r $(ATLAS_ARM_OUT)/muscles muscles/myoarm_atlas.partial
	cp $(ATLAS_ARM_OUT)/atlas_report.json muscles/myoarm_atlas.partial/
	rm -rf muscles/myoarm_atlas && mv muscles/myoarm_atlas.partial muscles/myoarm_atlas

# muscles/myobody_atlas: myobody's arms and shoulders from BodyParts3D (atlases/myoarm.yaml, both
# sides) and its legs from the Visible Human (atlases/rajagopal_legs.yaml), one run onto the
# other's library; the folder keeps BodyParts3D's licence, CC BY-SA 2.1 JP, and credits both
# (about 15 minutes on two cores).
ATLAS_BODY_OUT ?= build/atlas_myobody
atlas-myobody: $(STAMP)
	$(BIN)/axdf atlas $(ATLAS_UPPER) --onto poses/skeletons/myobody.yaml --map atlases/myoarm.yaml \
	  --muscles muscles/myobody --sides r,l --out $(ATLAS_BODY_OUT)_upper --overwrite
	$(BIN)/axdf atlas $(ATLAS) --onto poses/skeletons/myobody.yaml --map atlases/rajagopal_legs.yaml \
	  --muscles $(ATLAS_BODY_OUT)_upper/muscles --sides r,l --out $(ATLAS_BODY_OUT)_legs --overwrite
	rm -rf muscles/myobody_atlas.partial
	cp -r $(ATLAS_BODY_OUT)_legs/muscles muscles/myobody_atlas.partial
	{ cat $(ATLAS_BODY_OUT)_legs/muscles/README.md; echo; echo "## The arms and shoulders"; echo; \
	  sed -n '3p' $(ATLAS_BODY_OUT)_upper/muscles/README.md; echo; \
	  sed -n '/^## Credit/,$$p' $(ATLAS_BODY_OUT)_upper/muscles/README.md | tail -n +3; } \
	  > muscles/myobody_atlas.partial/README.md
	cp $(ATLAS_BODY_OUT)_upper/atlas_report.json muscles/myobody_atlas.partial/atlas_report_upper.json
	cp $(ATLAS_BODY_OUT)_legs/atlas_report.json muscles/myobody_atlas.partial/atlas_report_legs.json
	rm -rf muscles/myobody_atlas && mv muscles/myobody_atlas.partial muscles/myobody_atlas

import-mjcf: $(TEST_STAMP)
	$(BIN)/python scripts/myo_sim_xml.py myoarm $(MYO)/myoarm.xml
	$(BIN)/python scripts/myo_sim_xml.py myofullbody $(MYO)/myofullbody.xml
	$(BIN)/python scripts/myo_motion.py arm26 $(MYO)/myoarm.xml $(MYO)/myoarm_elbow.npz $(OSIM)/arm26/arm26_Kinematics_q.sto
	$(BIN)/python scripts/myo_motion.py gait $(MYO)/myofullbody.xml $(MYO)/myobody_gait.npz
	$(BIN)/axdf import mjcf $(MYO)/myoarm.xml --name myoarm --motion $(MYO)/myoarm_elbow.npz $(MJCF_MESHES) \
	  --out muscles/myoarm --muscles-out muscles/myoarm --skeleton-out poses/skeletons/myoarm.yaml \
	  --pose-out poses/myoarm_elbow.yaml --overwrite
	$(BIN)/axdf import mjcf $(MYO)/myofullbody.xml --name myobody --motion $(MYO)/myobody_gait.npz $(MJCF_MESHES) \
	  --out muscles/myobody --muscles-out muscles/myobody --skeleton-out poses/skeletons/myobody.yaml \
	  --pose-out poses/myobody_gait.yaml --overwrite
	$(BIN)/axdf retarget $(BVH) --onto poses/skeletons/myobody.yaml --map poses/maps/cmu_to_myobody.yaml --step 4 \
	  --name cmu_131_01_walk_myobody --out poses/retargeted/cmu_131_01_walk_myobody --overwrite

clean:
	rm -rf out .pytest_cache
