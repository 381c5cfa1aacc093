"""Contact: muscles push each other out of the way, bones push muscles.

Pure, batch-first functions over all muscles of one frame (the pipeline's FRAME-scope stage
calls :func:`apply`, which resolves every frame of a chunk with :func:`resolve_frame`).
Nothing is carried from one frame to the next: the result is a function of the frame's
no-contact meshes and bone poses only, so ``--jobs``, ``--resume`` and any ``--frames``
subset give the same bytes, and so does any number of threads.

Every muscle is a tessellated tube (a (U, A) grid whose first and last rows collapse to the
poles). Bones collide through a signed distance field per bone (:mod:`.fields`) and never
give way; muscles are queried in axis space (:mod:`.query`). A frame takes
tol.CONTACT_ITERATIONS Jacobi passes, every muscle against every other's previous pass:

1. the pushes the points of every ring ask for, and their low-pass around the ring and along
   the muscle (:mod:`.rings`), each asked for tol.CONTACT_RELAX times over;
2. every point moved by its ring's modes, soft-capped at tol.CONTACT_MAX_STEP a pass, so the
   surface stays as smooth as the muscle (no dents, no wrapping under a bone);
3. the volume solved exactly again (:mod:`.volume`).

Every step is a continuous function of the frame's meshes (soft fades and caps, no switching,
a fixed number of passes), so surfaces do not pop from frame to frame. A muscle nothing
touches is returned unchanged, bit for bit. The measures (:mod:`.measures`) give each
muscle's share of vertices inside another muscle and inside a bone, and its deepest point.

Modules: :mod:`.params` (settings and the kernels' named groups of arrays), :mod:`.fields`,
:mod:`.query` (public: the point queries :mod:`axdf_cli.model.pack` uses too), :mod:`.rings`,
:mod:`.volume`, :mod:`.measures`, :mod:`.frame`.
"""
from axdf_cli.model.contact import fields, frame, measures, params, query, rings, volume  # noqa: F401
from axdf_cli.model.contact.fields import BoneField, BoneFields, bone_field  # noqa: F401
from axdf_cli.model.contact.frame import ContactModel, apply, auto_yield, build, resolve_frame  # noqa: F401
from axdf_cli.model.contact.params import (CEN_COLUMNS, NMODES, QUERY_SIZE, SEG_GROUP, Fields, Lists,  # noqa: F401
                                           Mesh, PushParams, Rows, Work, pair_mask, pair_shares)
from axdf_cli.model.contact.volume import grid_volume, vertices_to_grid  # noqa: F401
