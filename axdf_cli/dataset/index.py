"""The index: one Parquet table of every sample (sequence x frame x view), in sequence order.

``parts`` lists the sample's meshes of the parts the stages add (comma-separated paths, in
the stages' order: the skin where the data set wears one); ``skin`` is the mesh of the part of
kind skin, and ``skin_passes`` names the EXR channels a skin adds (``under.id``, ``under.Z``,
``part.id``: an opaque skin's muscle-under-skin and body-part passes).

``visible_keypoints`` counts the keypoints visible in the sample (``labels.npz``'s ``visible``):
0 marks a sample whose view shows none of them (the subject out of view or hidden), so a
training loader can skip it (``index[index.visible_keypoints > 0]``).

Parquet (pyarrow) rather than CSV: typed columns (integers stay integers, paths stay strings,
no quoting rules), one line to open (``pd.read_parquet`` / ``pq.read_table``), a fraction of
the size, and column reads without parsing the rest. pyarrow writes the same bytes for the
same table (checked by the tests), so the index is as reproducible as the rest of the data
set. It is built from the sequences' records (``OUT/<sequence>/sequence.json``) alone, so a
single process, N workers, K shards joined by ``axdf dataset merge`` and a Ray cluster all
write the same file.
"""
from __future__ import annotations

import io
from pathlib import Path

from axdf_cli.fileio import atomic
from axdf_cli.errors import EnvironmentProblem

COLUMNS = ("sample", "sequence", "sequence_index", "source", "frame", "frame_index", "view", "view_index",
            "seed", "shard", "png", "exr", "labels", "amodal", "meshes", "mask", "depth", "visible_keypoints",
            "skin", "skin_passes", "parts")


def _pyarrow():
    try:
        import pyarrow as pa
        import pyarrow.parquet as pq
    except ImportError:
        raise EnvironmentProblem("cannot import pyarrow (the data set's index is Parquet)",
                                 "pip install 'pyarrow>=14' (make setup does this)") from None
    return pa, pq


def index_rows(records: list[dict], seed: int, shards: int, passes) -> dict:
    """Column name -> list of values, one row per (sequence, frame, view), in that order."""
    cols: dict = {c: [] for c in COLUMNS}
    n = 0
    for rec in records:
        name = rec["sequence"]
        for fi, frame in enumerate(rec["frames"]):
            for vi, view in enumerate(rec["views"]):
                cols["sample"].append(n)
                cols["sequence"].append(name)
                cols["sequence_index"].append(rec["index"])
                cols["source"].append(rec["source"])
                cols["frame"].append(frame)
                cols["frame_index"].append(fi)
                cols["view"].append(view)
                cols["view_index"].append(vi)
                cols["seed"].append(seed)
                cols["shard"].append(rec["index"] % shards)
                for ext in ("png", "exr"):
                    cols[ext].append(f"{name}/views/{view}/{frame:04d}.{ext}" if ext in passes else None)
                cols["labels"].append(f"{name}/labels.npz")
                cols["amodal"].append(f"{name}/amodal.json" if "amodal" in passes else None)
                cols["meshes"].append(f"{name}/meshes")
                for p in ("mask", "depth"):  # (views.VIEW_PNG_PASSES: <frame>.mask.png, .depth.png)
                    cols[p].append(f"{name}/views/{view}/{frame:04d}.{p}.png" if p in passes else None)
                cols["visible_keypoints"].append(_count(rec.get("visible_keypoints"), fi, vi))
                meshes = {p["name"]: _part_mesh(rec, p["name"], frame) for p in rec.get("parts", [])}
                skin = next((meshes[p["name"]] for p in rec.get("parts", []) if p["kind"] == "skin"), None)
                cols["skin"].append(f"{name}/{skin}" if skin else None)
                cols["parts"].append(",".join(f"{name}/{m}" for m in meshes.values() if m) or None)
                sp = rec.get("skin_passes")
                cols["skin_passes"].append(",".join(sp) if sp and "exr" in passes else None)
                n += 1
    return cols


def _part_mesh(rec: dict, part: str, frame: int) -> str | None:
    """A part's mesh file at ``frame`` among the record's files (``meshes/<part>/<part>_<frame>.<ext>``)."""
    return next((k for k in rec.get("files", {}) if k.startswith(f"meshes/{part}/{part}_{frame:04d}.")), None)


def _count(counts, fi: int, vi: int) -> int | None:
    """A record's visible keypoint count of frame ``fi``, view ``vi`` (None where it holds none)."""
    try:
        c = counts[fi][vi]
    except (TypeError, IndexError, KeyError):
        return None
    return c if type(c) is int and 0 <= c < 2 ** 31 else None


def index_bytes(records: list[dict], seed: int, shards: int, passes) -> bytes:
    pa, pq = _pyarrow()
    cols = index_rows(records, seed, shards, passes)
    types = {"sample": pa.int64(), "sequence_index": pa.int64(), "frame": pa.int64(), "frame_index": pa.int32(),
             "view_index": pa.int32(), "seed": pa.uint64(), "shard": pa.int32(), "visible_keypoints": pa.int32()}
    table = pa.table({c: pa.array(cols[c], type=types.get(c, pa.string())) for c in COLUMNS})
    buf = io.BytesIO()
    pq.write_table(table, buf, compression="zstd")
    return buf.getvalue()


def write_index(out: Path, records: list[dict], seed: int, shards: int, passes) -> str:
    """Write ``OUT/index.parquet`` atomically; return its sha256."""
    return atomic.write_bytes(Path(out) / "index.parquet", index_bytes(records, seed, shards, passes))
