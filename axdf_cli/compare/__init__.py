"""Golden-file comparison: ``compare_paths(actual, golden, tolerances) -> Report``.

Two run folders (or two files) are compared file by file. Each file's kind comes from its
name (one table, :data:`KINDS`); byte-identical files pass without being decoded. Files
missing or extra on either side fail, listed by name; a file that cannot be read (not a
regular file, a link out of the folder, a malformed or hostile file) is an ERROR verdict,
and the comparison goes on (:mod:`axdf_cli.compare.files` says what is read). Nothing here
prints; the pictures of failing images are written (atomically) when a ``diff_dir`` is given.
"""
from __future__ import annotations

import io
import os
import time
from pathlib import Path, PurePosixPath
from typing import Callable, Iterable

from axdf_cli.fileio.atomic import write_bytes
from axdf_cli.compare.files import list_files, nested, read_compared
from axdf_cli.compare.parts import differing_parts, pixel_parts
from axdf_cli.compare.result import ERROR, EXTRA, FAIL, MISSING, PASS, FileResult, Outcome, Report, read_side
from axdf_cli.compare.thresholds import FileTol, Tolerances, as_dict
from axdf_cli.errors import AxdfError, UsageError
from axdf_cli.formats import FORMATS, MeshReadError
from axdf_cli.fileio.yamlio import real_path

# file suffix -> kind; `manifest.json` is recognised by its whole name. Meshes come from the
# formats table: a per-frame format's file is a "mesh", a per-sequence one's a "sequence"
# (compared frame by frame); a USD stage (scene.usda) is compared value by value.
KINDS = {**{f.suffix: "mesh" if f.layout == "frame" else "sequence" for f in FORMATS.values()},
         ".png": "png", ".exr": "exr", ".csv": "table", ".json": "json", ".usda": "stage"}
MANIFEST = "manifest.json"

# kind -> the FileTol section that applies (None: no numeric tolerance)
TOL_SECTION = {"mesh": "mesh", "png": "png", "exr": "exr", "table": "table", "json": "json",
               "sequence": "mesh", "stage": "json", "manifest": None, "bytes": None}


def kind_of(name: str) -> str:
    base = name.rsplit("/", 1)[-1].lower()
    if base == MANIFEST:
        return "manifest"
    return KINDS.get(os.path.splitext(base)[1], "bytes")


def _compare_kind(kind: str, a: Path, g: Path, ab: bytes, gb: bytes, t: FileTol) -> Outcome:
    if kind == "mesh":
        from axdf_cli.compare.meshes import compare_mesh_files
        return compare_mesh_files(ab, gb, a.suffix.lower(), g.suffix.lower(), t.mesh)
    if kind == "sequence":
        from axdf_cli.compare.packed import compare_sequence_files
        return compare_sequence_files(a, g, t.mesh)
    if kind == "stage":
        from axdf_cli.compare.packed import compare_usd_layers
        return compare_usd_layers(a, g, t.json.atol, t.json.rtol)
    if kind == "png":
        from axdf_cli.compare.images import compare_png
        return compare_png(ab, gb, t.png)
    if kind == "exr":
        from axdf_cli.compare.images import compare_exr
        return compare_exr(ab, gb, t.exr)
    from axdf_cli.compare import tables
    if kind == "table":
        return tables.compare_csv(ab, gb, t.table)
    if kind == "json":
        return tables.compare_json(ab, gb, t.json)
    if kind == "manifest":
        return tables.compare_manifest(ab, gb)
    return tables.compare_bytes(ab, gb)


def check_path(side: str, p: Path) -> None:
    """A UsageError (exit 2) unless ``p`` is an existing folder or regular file."""
    if not p.exists():
        raise UsageError(f"{side} {p} does not exist", "give an existing run folder or file")
    if not p.is_dir() and not p.is_file():
        raise UsageError(f"{side} {p} is not a folder or a regular file", "compare two run folders or two files")


def check_paths(actual: Path, golden: Path) -> str:
    """'files' or 'folders'; a UsageError (exit 2) for a missing path, a path that is neither
    a folder nor a regular file (a FIFO, a device), or a file vs a folder."""
    check_path("ACTUAL", actual)
    check_path("GOLDEN", golden)
    if actual.is_dir() != golden.is_dir():
        fd = lambda p: "a folder" if p.is_dir() else "a file"  # noqa: E731
        raise UsageError(f"ACTUAL {actual} is {fd(actual)} but GOLDEN {golden} is {fd(golden)}",
                         "compare two run folders or two files")
    if actual.is_dir():
        return "folders"
    ka, kg = kind_of(actual.name), kind_of(golden.name)
    if ka != kg:
        raise UsageError(f"cannot compare a {ka} file ({actual.name}) with a {kg} file ({golden.name})",
                         "compare two files of the same kind (PLY and OBJ meshes compare with each other)")
    return "files"


def compare_paths(actual: Path | str, golden: Path | str, tolerances: Tolerances | None = None,
                  diff_dir: Path | str | None = None, exclude: Iterable[Path] = (),
                  progress: Callable[[int, int], None] | None = None) -> Report:
    """Compare two run folders or two files; ``progress(done, total)`` after each file.
    A folder inside the other (``compare A A/golden``) is left out of the outer one's list."""
    t0 = time.perf_counter()
    tolerances = tolerances or Tolerances()
    actual, golden = Path(actual), Path(golden)
    mode = check_paths(actual, golden)
    listing_errors: dict[str, str] = {}
    if mode == "files":
        pairs = [(golden.name, actual, golden)]
        roots = (None, None)
    else:
        exclude = list(exclude)
        inner = nested(actual, golden)
        if inner is not None and real_path(actual) != real_path(golden):
            exclude.append(inner)
        fa = {r: p for r, p in list_files(actual, exclude, listing_errors).items() if not tolerances.ignored(r)}
        fg = {r: p for r, p in list_files(golden, exclude, listing_errors).items() if not tolerances.ignored(r)}
        pairs = [(r, fa.get(r), fg.get(r)) for r in sorted(set(fa) | set(fg))]
        roots = (actual, golden)
    results = [FileResult(rel, "folder", ERROR, (why,)) for rel, why in sorted(listing_errors.items())]
    causes: list[str] = []
    for i, (rel, a, g) in enumerate(pairs):
        r = compare_pair(rel, a, g, tolerances, diff_dir, roots)
        if r.kind == "manifest":
            causes += r.notes
        results.append(r)
        if progress is not None:
            progress(i + 1, len(pairs))
    parts, bordering = differing_parts(results)
    return Report(str(actual), str(golden), tuple(results), tuple(causes), time.perf_counter() - t0,
                  tuple((k, tuple(v)) for k, v in parts.items()), tuple(bordering.items()))


def compare_pair(rel: str, a: Path | None, g: Path | None, tolerances: Tolerances,
                 diff_dir: Path | str | None = None, roots: tuple[Path | None, Path | None] = (None, None)
                 ) -> FileResult:
    """One file's verdict. Whatever is in the files, this returns: an unreadable or hostile
    file is an ERROR verdict with the reason, and so is (as a last resort, naming the
    exception) any other failure while comparing it, so that one file never aborts the
    comparison of a folder."""
    kind = kind_of(rel if a is None or g is None else g.name)
    if g is None:
        return FileResult(rel, kind, EXTRA, ("in actual, not in golden",))
    if a is None:
        return FileResult(rel, kind, MISSING, ("in golden, not in actual",))
    t0 = time.perf_counter()
    t = tolerances.for_path(rel)
    section = TOL_SECTION[kind]
    tol_dict = as_dict(t)[section] if section else None

    def error(reason: str) -> FileResult:
        return FileResult(rel, kind, ERROR, (reason,), tolerance=tol_dict, seconds=time.perf_counter() - t0)

    try:
        ab = read_side("actual", read_compared, a, roots[0])
        gb = read_side("golden", read_compared, g, roots[1])
        if kind == "sequence":  # a packed file's checksums and frame times, identical or not
            from axdf_cli.compare.packed import verify_files
            verify_files(a, g, ab == gb)
        if ab == gb and kind != "manifest":
            return FileResult(rel, kind, PASS, (), (), {"identical": True}, tol_dict,
                              seconds=time.perf_counter() - t0)
        out = _compare_kind(kind, a, g, ab, gb, t)
        by_part = pixel_parts(out.mask, rel, roots) if out.mask is not None else None
        picture = None
        if out.picture is not None and diff_dir is not None:
            from axdf_cli.fileio.runfolder import check_dirs

            check_dirs(Path(diff_dir), [PurePosixPath(rel).parent.as_posix()])  # never through a link
            picture = str(Path(diff_dir) / f"{rel}.diff.png")
            write_bytes(picture, _png_bytes(out.picture))
    except MeshReadError as e:  # Unreadable included
        return error(str(e))
    except RecursionError:
        return error("nested too deeply to compare")
    except MemoryError:
        return error("too large to compare in memory")
    except AxdfError:  # the environment (a missing package, an unwritable picture folder): not this file's fault
        raise
    except Exception as e:  # noqa: BLE001 - the last resort: this file's verdict, not the run's
        return error(f"could not be compared ({type(e).__name__}: {e}); please report this file")
    metrics = {"identical": ab == gb} | out.metrics | ({"failing_pixels_by_part": by_part} if by_part else {})
    return FileResult(rel, kind, PASS if out.ok else FAIL, out.reasons, out.notes, metrics, tol_dict,
                      picture, time.perf_counter() - t0)


PICTURE_MARK = b"axdf compare"  # a tEXt chunk "Software" in every picture: only those are ever removed


def _png_bytes(rgb) -> bytes:
    from PIL import Image
    from PIL.PngImagePlugin import PngInfo

    info = PngInfo()
    info.add_text("Software", PICTURE_MARK.decode())
    buf = io.BytesIO()
    Image.fromarray(rgb, "RGB").save(buf, format="PNG", pnginfo=info)
    return buf.getvalue()


def is_own_picture(path: Path) -> bool:
    """Whether ``path`` is a regular file (not a link) holding a picture :func:`_png_bytes` made
    (its Software text, which Pillow writes before the image data)."""
    import os
    import stat

    try:
        if not stat.S_ISREG(os.lstat(path).st_mode):
            return False
        with open(path, "rb") as f:
            head = f.read(256)
    except OSError:
        return False
    return head.startswith(b"\x89PNG") and b"tEXtSoftware\x00" + PICTURE_MARK in head


__all__ = ["compare_paths", "compare_pair", "check_path", "check_paths", "list_files", "kind_of", "nested", "KINDS",
           "Report", "FileResult", "Tolerances"]
