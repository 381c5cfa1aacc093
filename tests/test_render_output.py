"""Rendered frames agree with camera.json, EXR passes are typed and exact, output repeats."""
import json
from dataclasses import replace

import numpy as np
import pytest
from render_helpers import read_exr

from axdf_cli import tolerances as tol
from axdf_cli.errors import EnvironmentProblem
from axdf_cli.render.context import create_gl_context
from axdf_cli.render.renderer import render_frames
from axdf_cli.render.framefiles import benchmark_fps, render_sequence
from axdf_cli.specs.render import CameraSpec, RenderSettings
from axdf_cli.render.synthetic import synthetic_scene

SMALL = RenderSettings(enabled=True, size=(160, 120))


def project(cam: dict, P: np.ndarray):
    """(V, 3) world points -> (V, 2) pixel coordinates, (V,) camera depth, (V, 3) camera coords."""
    K, M = np.array(cam["K"]), np.array(cam["world_to_camera"])
    pc = P @ M[:3, :3].T + M[:3, 3]
    uvw = pc @ K.T
    return uvw[:, :2] / uvw[:, 2:3], pc[:, 2], pc


def pixel_hits(uv: np.ndarray, z: np.ndarray, faces: np.ndarray):
    """Which vertices have their pixel's centre inside one of their own front-facing projected
    triangles, and the exact depth of that triangle's plane there.

    uv: (V, 2) pixels, z: (V,) camera depth, faces: (T, 3). Returns (V,) bool, (V,) float64.
    """
    tri = uv[faces]  # (T, 3, 2)
    centre = np.floor(tri) + 0.5  # (T, 3, 2) pixel centre of each corner's pixel
    e1, e2 = tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]
    area = e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]  # (T,) < 0: front-facing (y down flips CCW)
    d = centre - tri[:, None, 0]  # (T, 3, 2)
    b1 = (d[..., 0] * e2[:, None, 1] - d[..., 1] * e2[:, None, 0]) / area[:, None]
    b2 = (e1[:, None, 0] * d[..., 1] - e1[:, None, 1] * d[..., 0]) / area[:, None]
    b0 = 1 - b1 - b2
    # distance (pixels) from the centre to the edge opposite each corner: b_i * |area| / |edge_i|
    edge = np.stack([np.linalg.norm(tri[:, 2] - tri[:, 1], axis=-1), np.linalg.norm(e2, axis=-1),
                     np.linalg.norm(e1, axis=-1)], -1)  # (T, 3)
    dist = np.stack([b0, b1, b2], -1) * np.abs(area)[:, None, None] / np.maximum(edge[:, None, :], 1e-12)
    # GL snaps vertices to 1/256 px (Mesa: 8 sub-pixel bits); keep centres clear of that
    inside = np.all(dist > tol.RENDER_EDGE_MARGIN_PX, axis=-1) & (area[:, None] < 0)  # (T, 3)
    inv_z = 1 / z[faces]  # (T, 3); 1/z is affine in screen space on a plane
    zc = 1 / (b0 * inv_z[:, None, 0] + b1 * inv_z[:, None, 1] + b2 * inv_z[:, None, 2])  # (T, 3)
    hit = np.zeros(len(uv), bool)
    depth = np.full(len(uv), np.nan)
    hit[faces[inside]] = True
    depth[faces[inside]] = zc[inside]
    return hit, depth


@pytest.mark.parametrize("settings", [
    replace(SMALL, view="auto"),
    replace(SMALL, view="sheet", size=(128, 128)),
    replace(SMALL, view="top", supersample=2, orbit=20.0),
    replace(SMALL, camera=CameraSpec((0.3, -0.5, 0.25), (0.0, 0.0, 0.0), fov=35.0)),
])
def test_vertices_land_in_their_id_mask_at_exr_depth(tmp_path, settings):
    scene, chunks = synthetic_scene(n_muscles=3, verts=800, n_frames=3)
    render_sequence(scene, chunks, settings, tmp_path)
    cam = json.loads((tmp_path / "camera.json").read_text())
    assert cam["ids"]["0"]["kind"] == "background"
    checked = 0
    for k, fr in enumerate(cam["frames"]):
        exr = read_exr(tmp_path / "frames" / f"{fr['frame']:04d}.exr")
        H, W = exr["id"].shape
        assert (W, H) == (cam["width"], cam["height"])
        for m, m_def in enumerate(scene.muscles):
            mid = m + 1
            assert cam["ids"][str(mid)] == {"kind": "muscle", "name": m_def.name}
            P = chunks[k].positions[m][0].astype(np.float64)
            for c in fr["cameras"]:
                uv, z, pc = project(c, P)
                x0, y0, w, h = c["viewport"]
                # automatic and explicit framing keep every vertex inside its panel
                assert np.all((uv[:, 0] > x0) & (uv[:, 0] < x0 + w) & (uv[:, 1] > y0) & (uv[:, 1] < y0 + h))
                iu, iv = np.floor(uv[:, 0]).astype(int), np.floor(uv[:, 1]).astype(int)
                Zpix, idpix = exr["Z"][iv, iu], exr["id"][iv, iu]
                hit, zplane = pixel_hits(uv, z, m_def.faces)
                # the pixel centre lies on this muscle's front surface: unless something nearer
                # covers it, the pixel carries this muscle's id and that surface's depth
                covered = (idpix != mid) & (idpix != 0) & (Zpix < zplane)
                sel = hit & ~covered
                assert np.all(idpix[sel] == mid), f"{(idpix[sel] != mid).sum()} of {sel.sum()} outside mask"
                err = np.abs(Zpix[sel] - zplane[sel])
                assert np.all(err <= tol.RENDER_DEPTH_RTOL * zplane[sel]), err.max()
                # and the vertex itself is within a pixel's footprint of that depth
                foot = z[sel] / np.array(c["K"])[0, 0]
                assert np.all(np.abs(Zpix[sel] - z[sel]) <= 10 * foot)
                checked += int(sel.sum())
    assert checked > 500


def test_exr_channels_types_and_exact_ids(tmp_path):
    scene, chunks = synthetic_scene(n_muscles=3, verts=400, n_frames=2)
    res = render_sequence(scene, chunks, SMALL, tmp_path)
    assert res["gl_renderer"] and res["gl_version"]
    assert set(res["files"]) == {"frames/0000.png", "frames/0000.exr", "frames/0001.png",
                                 "frames/0001.exr", "camera.json"}
    import OpenEXR

    with OpenEXR.File(str(tmp_path / "frames" / "0000.exr"), separate_channels=True) as f:
        ch = f.channels()
        assert f.header()["compression"] == OpenEXR.ZIP_COMPRESSION
        types = {n: c.pixels.dtype for n, c in ch.items()}
    assert types == {"R": np.float16, "G": np.float16, "B": np.float16, "A": np.float16,
                     "Z": np.float32, "N.X": np.float32, "N.Y": np.float32, "N.Z": np.float32,
                     "id": np.uint32}
    exr = read_exr(tmp_path / "frames" / "0000.exr")
    ids = exr["id"]
    assert set(np.unique(ids)) == {0, 1, 2, 3, 4}  # background, 3 muscles, the bone
    bg = ids == 0
    assert np.all(exr["Z"][bg] == 0) and np.all(exr["Z"][~bg] > 0)
    n = np.stack([exr["N.X"], exr["N.Y"], exr["N.Z"]], -1)
    assert np.all(n[bg] == 0)
    assert np.abs(np.linalg.norm(n[~bg], axis=-1) - 1).max() < 1e-5
    assert np.all(exr["A"][~bg] == 1)
    # PNG agrees with the EXR coverage: opaque background here, so alpha 255 everywhere
    from PIL import Image

    png = np.asarray(Image.open(tmp_path / "frames" / "0000.png"))
    assert png.shape == (120, 160, 4) and png.dtype == np.uint8 and np.all(png[..., 3] == 255)


def test_two_renders_are_byte_identical(tmp_path):
    scene, chunks = synthetic_scene(n_muscles=2, verts=400, n_frames=2)
    s = replace(SMALL, wireframe=True, background=(0, 0, 0, 0))
    a = render_sequence(scene, chunks, s, tmp_path / "a")
    b = render_sequence(scene, chunks, s, tmp_path / "b")
    assert a["files"] == b["files"]
    for rel in a["files"]:
        assert (tmp_path / "a" / rel).read_bytes() == (tmp_path / "b" / rel).read_bytes(), rel


def test_transparent_background_and_fixed_camera(tmp_path):
    scene, chunks = synthetic_scene(n_muscles=2, verts=300, n_frames=3)
    render_sequence(scene, chunks, replace(SMALL, background=(0, 0, 0, 0)), tmp_path)
    from PIL import Image

    png = np.asarray(Image.open(tmp_path / "frames" / "0001.png"))
    exr = read_exr(tmp_path / "frames" / "0001.exr")
    def all3x3(mask, edge):  # True where the pixel and its 8 neighbours are all in mask
        pad = np.pad(mask, 1, constant_values=edge)
        return np.all([pad[1 + di:121 + di, 1 + dj:161 + dj] for di in (-1, 0, 1) for dj in (-1, 0, 1)], 0)

    bg = exr["id"] == 0
    far_bg, inner = all3x3(bg, True), all3x3(~bg, False)
    assert far_bg.any() and np.all(png[..., 3][far_bg] == 0) and np.all(exr["A"][far_bg] == 0)
    assert inner.any() and np.all(png[..., 3][inner] == 255)
    cam = json.loads((tmp_path / "camera.json").read_text())
    mats = [fr["cameras"][0]["world_to_camera"] for fr in cam["frames"]]
    assert all(m == mats[0] for m in mats)  # no jumping without orbit


def test_gl_context_has_no_error_after_rendering():
    scene, chunks = synthetic_scene(n_muscles=2, verts=300, n_frames=2)
    ctx = create_gl_context()
    try:
        imgs = list(render_frames(ctx, scene, chunks, replace(SMALL, wireframe=True)))
        assert ctx.error == "GL_NO_ERROR"
        assert [i.frame for i in imgs] == [0, 1]
        assert imgs[0].rgba.shape == (120, 160, 4) and imgs[0].ids.dtype == np.uint32
    finally:
        ctx.release()


def test_missing_egl_library_is_an_environment_problem():
    with pytest.raises(EnvironmentProblem) as e:
        create_gl_context(libegl="/nonexistent/libEGL.so.1")
    assert "apt-get install -y libegl1 libegl-mesa0 libgl1-mesa-dri libgles2" in e.value.hint


def test_benchmark_reports_fps(tmp_path):
    r = benchmark_fps(size=(64, 64), n_muscles=2, verts=200, frames=2, out_dir=tmp_path)
    assert r["frames"] == 2 and r["render_fps"] > 0 and r["write_fps"] > 0


def _with_skin(scene, chunks, radius: float = 0.2):
    """The synthetic scene inside a sphere of ``radius`` (its 'skin')."""
    from axdf_cli.parts import Kind
    from axdf_cli.render.scene import SceneLayer
    from axdf_cli.render.synthetic import uv_sphere

    unit, faces = uv_sphere(16, 32)
    pos = (unit * radius).astype(np.float32)[None]
    nrm = unit.astype(np.float32)[None]
    skinned = replace(scene, layers=(SceneLayer("skin", Kind.SKIN, faces, (0.75, 0.41, 0.31)),),
                      bounds=np.array([[-radius] * 3, [radius] * 3]))
    return skinned, [replace(c, layers=((pos, nrm),)) for c in chunks]


def test_a_skin_is_drawn_opaque_see_through_or_not_at_all():
    """Opaque: the id pass sees the skin (its id after the bones) and no muscle; see-through:
    the data passes are exactly those without a skin and the picture is the muscles' tinted by
    it (every muscle pixel changes, and keeps more of its colour than the opaque skin leaves);
    off: byte-identical to no skin at all. camera.json's ids name the skin when it is opaque."""
    from axdf_cli.render.renderer import id_map, skin_id

    scene, chunks = synthetic_scene(n_muscles=3, verts=400, n_frames=1)
    skinned, skin_chunks = _with_skin(scene, chunks)
    cam = CameraSpec((0.0, -0.9, 0.1), (0.0, 0.0, 0.0), fov=40.0)
    base = replace(SMALL, camera=cam)
    ctx = create_gl_context()
    try:
        def one(sc, ch, view):
            return list(render_frames(ctx, sc, ch, replace(base, skin=view)))[0]

        bare = one(scene, chunks, "see-through")
        off, see, opaque = (one(skinned, skin_chunks, v) for v in ("off", "see-through", "opaque"))
        assert ctx.error == "GL_NO_ERROR"
    finally:
        ctx.release()
    muscle = (bare.ids >= 1) & (bare.ids <= 3)
    assert muscle.sum() > 500
    assert np.array_equal(off.rgba, bare.rgba) and np.array_equal(off.ids, bare.ids)
    assert np.array_equal(see.ids, bare.ids) and np.array_equal(see.depth, bare.depth)
    sid = skin_id(skinned)
    assert sid == 5 and np.all(opaque.ids[muscle] == sid)  # 3 muscles, 1 bone, then the skin
    assert not np.isin(opaque.ids, [1, 2, 3]).any()
    d_see = np.abs(see.rgba[..., :3] - bare.rgba[..., :3]).sum(-1)[muscle]
    d_opaque = np.abs(opaque.rgba[..., :3] - bare.rgba[..., :3]).sum(-1)[muscle]
    assert np.all(d_see > 1e-3) and np.median(d_see) < 0.6 * np.median(d_opaque)
    assert id_map(skinned, True, "opaque")[str(sid)] == {"kind": "skin", "name": "skin"}
    assert str(sid) not in id_map(skinned, True, "see-through")


def test_renderers_one_after_another_in_one_context_leave_no_gl_error():
    """A renderer releases its framebuffers with the default one bound: the next renderer in
    the same context (a data set renders scene after scene) makes its own without a GL error."""
    scene, chunks = synthetic_scene(n_muscles=2, verts=300, n_frames=1)
    ctx = create_gl_context()
    try:
        for _ in range(3):
            list(render_frames(ctx, scene, chunks, SMALL))
            assert ctx.error == "GL_NO_ERROR"
    finally:
        ctx.release()


def test_the_muscle_under_skin_pass_names_the_nearest_muscle_beneath_each_skin_pixel():
    """An opaque skin's pixels unprojected through the camera lie on the skin's triangles
    (within 0.1 mm); the pass names, for >= 99% of those within SKIN_UNDER_MAX_DEPTH of a muscle,
    the muscle whose surface a dense sampling finds nearest (the bar is 95%), and its
    depth is that distance within 1 mm; farther pixels name none."""
    import igl
    import trimesh
    from scipy.spatial import cKDTree

    from axdf_cli.render.camera import sequence_cameras
    from axdf_cli.render.renderer import skin_id
    from axdf_cli.render.under import NO_MUSCLE, under_skin, unproject

    scene, chunks = synthetic_scene(n_muscles=3, verts=600, n_frames=1, with_bone=False)
    skinned, skin_chunks = _with_skin(scene, chunks, radius=0.16)
    settings = replace(SMALL, size=(200, 160), skin="opaque", camera=CameraSpec((0.2, -0.8, 0.3), (0, 0, 0), fov=35.0))
    ctx = create_gl_context()
    try:
        img = list(render_frames(ctx, skinned, skin_chunks, settings))[0]
    finally:
        ctx.release()
    cam = sequence_cameras(skinned, settings)[0][0]
    K, w2c = np.asarray(cam.K), np.asarray(cam.world_to_camera)
    meshes = [(p[0], m.faces) for p, m in zip(skin_chunks[0].positions, skinned.muscles)]
    sid = skin_id(skinned)
    uid, udepth = under_skin(img.depth, img.ids, sid, K, w2c, meshes)
    skin = img.ids == sid
    assert skin.sum() > 5000 and np.all(uid[~skin] == NO_MUSCLE) and np.all(udepth[~skin] == 0)
    pts = unproject(img.depth, skin, K, w2c)
    on_skin = igl.point_mesh_squared_distance(pts, skin_chunks[0].layers[0][0][0].astype(np.float64), skinned.skin.faces)[0]
    assert np.sqrt(on_skin).max() < 1e-4  # the depth pass, unprojected, lies on the skin's triangles
    samples, owner = [], []
    for k, (v, f) in enumerate(meshes):
        s = trimesh.sample.sample_surface_even(trimesh.Trimesh(v, f, process=False), 40000, seed=k)[0]
        samples.append(s)
        owner.append(np.full(len(s), k + 1))
    d, i = cKDTree(np.concatenate(samples)).query(pts)
    near = d < tol.SKIN_UNDER_MAX_DEPTH - 1e-3
    far = d > tol.SKIN_UNDER_MAX_DEPTH + 1e-3  # (the synthetic skin's poles lie far from every muscle)
    assert near.sum() > 2000 and far.sum() > 500 and np.all(uid[skin][far] == NO_MUSCLE)
    agree = np.mean(np.concatenate(owner)[i][near] == uid[skin][near])
    assert agree >= 0.99, agree
    assert np.median(np.abs(d - udepth[skin])[near]) < 1e-3
    assert np.all(udepth[skin][near] <= d[near] + 1e-6)  # exact to the triangles: never farther than a sample
