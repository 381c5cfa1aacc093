"""Safe YAML reading that keeps every value's file position, and a small schema reader.

Documents are composed with PyYAML's ``SafeLoader`` into nodes and converted here into
:class:`YMap` / :class:`YSeq` (a ``dict`` / ``list`` that remember the line and column of
their keys and items). Hostile input is refused with an :class:`InputError` that names the
position: non-UTF-8 bytes, non-standard tags (``!!python/object`` ...), alias bombs (the
expanded document may hold at most ``YAML_MAX_NODES`` nodes), deep nesting, duplicate keys,
and non-finite or huge numbers.

:class:`Fields` reads one mapping against a schema: every read key is checked for type and
range, and :meth:`Fields.done` reports any key that was not read as unknown, listing the
allowed ones. Given the schema's keys up front (``keys=``), unknown keys are reported before
anything is read, so a misspelt key is never reported as a missing one; either way the
nearest allowed key is suggested (``did you mean 'radii'?``).
"""
from __future__ import annotations

import math
import os
import re
import stat
from pathlib import Path
from typing import Any, Iterable, Sequence

import yaml

from axdf_cli import tolerances as tol
from axdf_cli.errors import InputError, Mark, did_you_mean, nearest  # noqa: F401  (the suggestions every spec reader gives)

NAME_RE = re.compile(r"[A-Za-z0-9_.-]+")  # whole names only: fullmatch (`$` would let "a\n" by)
#: Longest name (characters = bytes: names are ASCII). Names become file names: the longest
#: derived one is a temporary ``.axdf-tmp-<pid>-<muscle>_<frame>.ply`` (18 + name + 13 bytes
#: for a frame up to 10,000,000), which must fit the usual 255-byte limit; 200 leaves room.
NAME_MAX = 200
NAME_ALLOWED = f"names use letters, digits, '_', '.', '-' (not '.' or '..' alone), at most {NAME_MAX} characters"


_STD_TAGS = {
    "tag:yaml.org,2002:str",
    "tag:yaml.org,2002:int",
    "tag:yaml.org,2002:float",
    "tag:yaml.org,2002:bool",
    "tag:yaml.org,2002:null",
}
_MAP_TAG = "tag:yaml.org,2002:map"
_SEQ_TAG = "tag:yaml.org,2002:seq"
_FLOAT_TAG = "tag:yaml.org,2002:float"


class _Loader(getattr(yaml, "CSafeLoader", yaml.SafeLoader)):
    """PyYAML's safe loader (libyaml's parser when PyYAML was built with it: much faster on
    large pose files; the same safe constructor and the same marks either way), with YAML
    1.2's floats: YAML 1.1 (PyYAML) reads ``1e-5``, ``2E3`` and ``1.0e9`` as strings
    because its float needs a dot and a signed exponent. Registered on this class only
    (``add_implicit_resolver`` copies the resolver table into the subclass), so PyYAML's
    own loaders are unchanged."""


# the exponent forms YAML 1.2's core schema reads as floats and YAML 1.1's resolver misses;
# plain numbers with a dot and a signed exponent (1.5e-3) already resolve to floats
_Loader.add_implicit_resolver(
    _FLOAT_TAG, re.compile(r"^[-+]?(?:[0-9][0-9_]*(?:\.[0-9_]*)?|\.[0-9][0-9_]*)[eE][-+]?[0-9]+$"),
    list("-+0123456789."))
_LOADER = _Loader


class YMap(dict):
    """A mapping from YAML that knows where it and each of its keys and values are."""

    mark: Mark
    key_marks: dict
    value_marks: dict

    def key_mark(self, key) -> Mark:
        return self.key_marks.get(key, self.mark)

    def value_mark(self, key) -> Mark:
        return self.value_marks.get(key, self.mark)


class YSeq(list):
    """A sequence from YAML that knows where it and each of its items are."""

    mark: Mark
    item_marks: list

    def item_mark(self, i: int) -> Mark:
        return self.item_marks[i] if 0 <= i < len(self.item_marks) else self.mark


def mark_of(value, default: Mark) -> Mark:
    return getattr(value, "mark", default)


def _mark(file: str, m) -> Mark:
    return Mark(file, m.line + 1, m.column + 1)


class FileRefused(ValueError):
    """A path that is not a regular file (``allowed`` None: the caller says what it wanted),
    or a file over the size limit (see :func:`read_regular`)."""

    def __init__(self, problem: str, allowed: str | None = None):
        self.problem, self.allowed = problem, allowed
        super().__init__(problem if allowed is None else f"{problem}; {allowed}")


_KINDS = ((stat.S_ISDIR, "a folder"), (stat.S_ISFIFO, "a FIFO (named pipe)"), (stat.S_ISCHR, "a character device"),
          (stat.S_ISBLK, "a block device"), (stat.S_ISSOCK, "a socket"))
_CHUNK = 1 << 20


def not_regular(mode: int) -> str | None:
    """None for a regular file's ``st_mode``; otherwise what it is ("is a FIFO (named pipe), not a regular file")."""
    if stat.S_ISREG(mode):
        return None
    kind = next((name for test, name in _KINDS if test(mode)), "not a file")
    return f"is {kind}, not a regular file"


def read_regular(path: Path | str, limit: int) -> bytes:
    """The bytes of the regular file at ``path``, at most ``limit`` bytes.

    The one low-level reader of input files (YAML, .sto, XML, meshes) and of compared files.
    The path is checked with ``stat`` before it is opened and the open file again with
    ``fstat`` (no window between the check and the read): a FIFO, device, socket or folder is
    refused (a FIFO would block forever, ``/dev/zero`` never ends). It is opened with
    ``O_NONBLOCK`` so that even a FIFO swapped in after the check cannot block the open, and
    read in chunks up to ``limit + 1`` bytes (a file over the limit, or one growing past it
    while read, is refused without reading it whole). Raises :class:`FileRefused`, or
    ``OSError`` for a missing file, a symlink loop or a permission problem.
    """
    problem = not_regular(os.stat(path).st_mode)
    if problem:
        raise FileRefused(problem)
    fd = os.open(path, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_NOCTTY", 0)
                 | getattr(os, "O_CLOEXEC", 0))
    with os.fdopen(fd, "rb", buffering=0) as f:
        st = os.fstat(fd)
        problem = not_regular(st.st_mode)
        if problem:
            raise FileRefused(problem)
        if st.st_size > limit:
            raise FileRefused(f"file is {st.st_size} bytes", f"at most {limit} bytes are read")
        parts, n = [], 0
        want = st.st_size + 1  # one byte more than stat says: sees a file that grew
        while n <= limit:
            b = f.read(min(want, limit + 1 - n))
            if not b:
                break
            parts.append(b)
            n += len(b)
            want = _CHUNK
        if n > limit:
            raise FileRefused(f"file is more than {limit} bytes", f"at most {limit} bytes are read")
    return b"".join(parts)


def read_input(path: Path | str, display: str | None = None, allowed: str = "an existing file",
               limit: int = tol.INPUT_MAX_BYTES) -> bytes:
    """The bytes of an input file (at most ``limit``); a missing file, a folder, a FIFO or
    device, a symlink loop, an unreadable or oversize file is an InputError naming it."""
    display = display or str(path)
    try:
        return read_regular(path, limit)
    except FileNotFoundError:
        raise InputError(Mark(display), "file not found", allowed) from None
    except FileRefused as e:
        raise InputError(Mark(display), e.problem, e.allowed or allowed) from None
    except OSError as e:
        raise InputError(Mark(display), f"cannot read ({e.strerror or e})", allowed) from None


def real_path(path: Path | str) -> Path:
    """``path`` absolute with symbolic links resolved as far as they go; never raises on a
    symlink loop (``Path.resolve`` raises RuntimeError there in Python 3.11): the loop
    stays in the path and reading it gives an InputError naming it."""
    return Path(os.path.realpath(path))


def read_text(path: Path, display: str | None = None, allowed: str = "an existing YAML file",
              max_bytes: int | None = None) -> str:
    """Read a UTF-8 text file of at most ``max_bytes`` (default ``YAML_MAX_BYTES``); refuse
    binary, oversize or undecodable files with a position."""
    display = display or str(path)
    data = read_input(path, display, allowed, limit=tol.YAML_MAX_BYTES if max_bytes is None else max_bytes)
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as e:
        before = data[: e.start]
        line = before.count(b"\n") + 1
        col = e.start - (before.rfind(b"\n") + 1) + 1
        raise InputError(Mark(display, line, col), f"byte 0x{data[e.start]:02x} is not UTF-8",
                         "input files must be UTF-8 text") from None
    if "\x00" in text:
        off = text.index("\x00")
        line = text.count("\n", 0, off) + 1
        col = off - (text.rfind("\n", 0, off) + 1) + 1
        raise InputError(Mark(display, line, col), "NUL character in text", "input files must be text")
    return text


def load_yaml(path: Path | str, display: str | None = None) -> Any:
    """Load one YAML document safely; return YMap/YSeq/scalars carrying positions."""
    display = display or str(path)
    text = read_text(Path(path), display)
    return parse_yaml(text, display)


_OPEN_EVENTS = (yaml.SequenceStartEvent, yaml.MappingStartEvent)
_CLOSE_EVENTS = (yaml.SequenceEndEvent, yaml.MappingEndEvent)


def _check_depth(text: str, display: str) -> None:
    """Refuse nesting deeper than YAML_MAX_DEPTH before composing: libyaml's composer
    recurses in C, and a document nested 50,000 deep (100 KB of ``- - - ...``) crashes the
    interpreter instead of raising. One pass over the parser's events (iterative)."""
    loader = _LOADER(text)
    depth = 0
    try:
        while loader.check_event():
            event = loader.get_event()
            if isinstance(event, _OPEN_EVENTS):
                depth += 1
                if depth > tol.YAML_MAX_DEPTH:
                    raise InputError(_mark(display, event.start_mark), "document nested too deeply",
                                     f"at most {tol.YAML_MAX_DEPTH} levels")
            elif isinstance(event, _CLOSE_EVENTS):
                depth -= 1
    finally:
        loader.dispose()


_NESTING_LIMITED: bool | None = None


def _loader_limits_nesting() -> bool:
    """Whether the YAML loader refuses deep nesting itself while scanning (libyaml through
    PyYAML 6.0.4 stops at 1,000 levels): then composing cannot recurse too deep and the
    event pass of :func:`_check_depth` is not needed (:data:`tol.YAML_MAX_DEPTH` is still
    enforced while converting). Asked once per process, on a 2,000-deep document."""
    global _NESTING_LIMITED
    if _NESTING_LIMITED is None:
        loader = _LOADER("[" * 2000 + "]" * 2000)
        try:
            loader.get_single_node()
            _NESTING_LIMITED = False
        except yaml.YAMLError as e:
            _NESTING_LIMITED = "nesting depth" in str(e)
        except RecursionError:
            _NESTING_LIMITED = False
        finally:
            loader.dispose()
    return _NESTING_LIMITED


def parse_yaml(text: str, display: str) -> Any:
    loader = _LOADER(text)
    try:
        if not _loader_limits_nesting():
            _check_depth(text, display)
        node = loader.get_single_node()
    except yaml.MarkedYAMLError as e:
        m = e.problem_mark or e.context_mark
        where = _mark(display, m) if m is not None else Mark(display)
        problem = e.problem or e.context or "YAML syntax error"
        if "nesting depth" in problem:  # libyaml's own limit (PyYAML 6.0.4's), met while scanning ahead
            raise InputError(where, "document nested too deeply", f"at most {tol.YAML_MAX_DEPTH} levels") from None
        raise InputError(where, f"YAML syntax error: {problem}", "see https://yaml.org/spec/1.2.2/") from None
    except yaml.YAMLError as e:
        raise InputError(Mark(display), f"YAML error: {e}") from None
    except RecursionError:  # not expected after _check_depth; a last resort
        raise InputError(Mark(display), "document nested too deeply", f"at most {tol.YAML_MAX_DEPTH} levels") from None
    if node is None:
        return None
    # Without an alias (no "*" anywhere) a document is as many values as it has nodes, bounded
    # by the file's size (YAML_MAX_BYTES); only aliases can expand it past that.
    aliases = "*" in text
    if aliases:
        _check_expanded_size(node, display)
    conv = _Converter(loader, display, tol.YAML_MAX_NODES if aliases else None)
    try:
        return conv.convert(node, 0, _mark(display, node.start_mark))
    finally:
        loader.dispose()


def _check_expanded_size(root, display: str) -> None:
    """Refuse documents whose aliases expand past YAML_MAX_NODES values, before expanding
    them: sizes are counted once per distinct node (an alias bomb is refused in milliseconds)."""
    size: dict[int, int] = {}
    order: list = []
    stack = [root]
    seen: set[int] = set()
    while stack:  # post-order without recursion
        n = stack.pop()
        if id(n) in seen:
            continue
        seen.add(id(n))
        order.append(n)
        if isinstance(n, yaml.SequenceNode):
            stack.extend(n.value)
        elif isinstance(n, yaml.MappingNode):
            for k, v in n.value:
                stack.extend((k, v))
    for n in reversed(order):
        if isinstance(n, yaml.SequenceNode):
            total = 1 + sum(size.get(id(c), 1) for c in n.value)
        elif isinstance(n, yaml.MappingNode):
            total = 1 + sum(size.get(id(k), 1) + size.get(id(v), 1) for k, v in n.value)
        else:
            total = 1
        size[id(n)] = total
        if total > tol.YAML_MAX_NODES:
            raise InputError(_mark(display, n.start_mark), f"document expands to more than {tol.YAML_MAX_NODES} "
                             "values (an alias bomb?)", "use fewer aliases")


_INT_TAG, _FLOAT_TAG, _STR_TAG = "tag:yaml.org,2002:int", "tag:yaml.org,2002:float", "tag:yaml.org,2002:str"
_PLAIN_INT = re.compile(r"[-+]?(?:0|[1-9][0-9]*)\Z")


def _plain_scalar(node) -> tuple[bool, Any]:
    """(True, value) for the common scalars, read as PyYAML's constructors read them but
    without their per-node cost: a string, a decimal integer without a leading zero, a
    float without ``_`` or ``:`` (Python's float() reads those as YAML 1.1 does); (False,
    None) for the rest (octal, hex, sexagesimal, .inf, booleans, null: the constructors)."""
    tag, v = node.tag, node.value
    if tag == _STR_TAG:
        return True, v
    if tag == _FLOAT_TAG and "_" not in v and ":" not in v:
        try:
            return True, float(v)
        except ValueError:
            return False, None
    if tag == _INT_TAG and _PLAIN_INT.match(v):
        return True, int(v)  # (ValueError past Python's 4,300 digits: the caller's message)
    return False, None


class _Converter:
    def __init__(self, loader: yaml.SafeLoader, file: str, max_values: int | None = tol.YAML_MAX_NODES):
        self.loader = loader
        self.file = file
        self.count = 0
        self.max_values = max_values  # None: no aliases, the document is its own size

    def convert(self, node, depth: int, where: Mark):
        """The value of ``node`` (at ``where``), with positions."""
        self.count += 1
        if self.max_values is not None and self.count > self.max_values:
            raise InputError(where, f"document expands to more than {self.max_values} values "
                             "(an alias bomb?)", "use fewer aliases")
        if depth > tol.YAML_MAX_DEPTH:
            raise InputError(where, "document nested too deeply", f"at most {tol.YAML_MAX_DEPTH} levels")
        if isinstance(node, yaml.ScalarNode):
            if node.tag not in _STD_TAGS:
                raise InputError(where, f"tag {node.tag!r} is not allowed",
                                 "plain strings, numbers, booleans and null only")
            try:
                done, value = _plain_scalar(node)
                if not done:
                    value = self.loader.construct_object(node, deep=True)
            except yaml.YAMLError as e:
                raise InputError(where, f"bad value: {getattr(e, 'problem', e)}") from None
            except ValueError:  # an integer of more digits than Python converts (4300)
                raise InputError(where, f"number {node.value[:20]}... of {len(node.value)} characters",
                                 f"numbers within ±{tol.MAX_ABS_NUMBER:g}") from None
            if isinstance(value, float) and not math.isfinite(value):
                raise InputError(where, f"number {node.value!r} is not finite", "finite numbers only")
            return value
        if isinstance(node, yaml.SequenceNode):
            if node.tag != _SEQ_TAG:
                raise InputError(where, f"tag {node.tag!r} is not allowed", "plain lists only")
            out = YSeq()
            out.mark = where
            out.item_marks = []
            for item in node.value:
                m = _mark(self.file, item.start_mark)
                out.item_marks.append(m)
                out.append(self.convert(item, depth + 1, m))
            return out
        if isinstance(node, yaml.MappingNode):
            if node.tag != _MAP_TAG:
                raise InputError(where, f"tag {node.tag!r} is not allowed", "plain mappings only")
            out = YMap()
            out.mark = where
            out.key_marks = {}
            out.value_marks = {}
            for knode, vnode in node.value:
                kmark = _mark(self.file, knode.start_mark)
                if not isinstance(knode, yaml.ScalarNode):
                    raise InputError(kmark, "mapping key is not a plain value", "keys are names or numbers")
                key = self.convert(knode, depth + 1, kmark)
                if isinstance(key, (list, dict)):
                    raise InputError(kmark, "mapping key is not a plain value", "keys are names or numbers")
                if key in out:
                    first = out.key_marks[key]
                    raise InputError(kmark, f"duplicate key {key!r} (first at line {first.line})",
                                     "each key once")
                out.key_marks[key] = kmark
                vmark = out.value_marks[key] = _mark(self.file, vnode.start_mark)
                out[key] = self.convert(vnode, depth + 1, vmark)
            return out
        raise InputError(where, "unsupported YAML node")


# ----------------------------------------------------------------------------- schema reading

def _type_name(v) -> str:
    if isinstance(v, str) and len(v) > NAME_MAX:
        return f"a string of {len(v)} characters"
    if v is None:
        return "null"
    if isinstance(v, bool):
        return "a boolean"
    if isinstance(v, (int, float)):
        return f"the number {v!r}"
    if isinstance(v, str):
        return f"the string {v!r}" if len(v) < 40 else "a string"
    if isinstance(v, list):
        return "a list"
    if isinstance(v, dict):
        return "a mapping"
    return type(v).__name__


def check_number(v, where: Mark, what: str, lo=None, hi=None, lo_open=False, integer=False) -> float:
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        raise InputError(where, f"{what} is {_type_name(v)}",
                         f"{what} must be {'an integer' if integer else 'a number'}")
    if integer and not isinstance(v, int):
        if float(v).is_integer():
            v = int(v)
        else:
            raise InputError(where, f"{what} is {v!r}", f"{what} must be an integer")
    if isinstance(v, float) and not math.isfinite(v):
        raise InputError(where, f"{what} is not finite", "finite numbers only")
    if abs(v) > tol.MAX_ABS_NUMBER:
        raise InputError(where, f"{what} is {v!r}, too large", f"|{what}| <= {tol.MAX_ABS_NUMBER:g}")
    rng = _range_text(lo, hi, lo_open)
    if lo is not None and (v < lo or (lo_open and v == lo)):
        raise InputError(where, f"{what} is {v!r}", f"{what} must be {rng}")
    if hi is not None and v > hi:
        raise InputError(where, f"{what} is {v!r}", f"{what} must be {rng}")
    return v


def _range_text(lo, hi, lo_open) -> str:
    if lo is not None and hi is not None:
        return f"in {'(' if lo_open else '['}{lo}, {hi}]"
    if lo is not None:
        return f"{'>' if lo_open else '>='} {lo}"
    if hi is not None:
        return f"<= {hi}"
    return "a number"


def unique_names(bases, taken=()) -> list[str]:
    """``bases`` made unique, in order: a name already used (or in ``taken``) gets ``_2``,
    ``_3``, ... appended, the first free one."""
    seen = set(taken)
    out = []
    for base in bases:
        name, k = base, 1
        while name in seen:
            k += 1
            name = f"{base}_{k}"
        seen.add(name)
        out.append(name)
    return out


def is_name(v) -> bool:
    """Whether ``v`` is an axdf name (a muscle, bone, sequence...: it becomes a file or folder
    name, so never ``.`` or ``..``)."""
    return isinstance(v, str) and bool(NAME_RE.fullmatch(v)) and v not in (".", "..") and len(v) <= NAME_MAX


def check_name(v, where: Mark, what: str) -> str:
    if not is_name(v):
        # YAML reads 1e-5, 12 or true as a number or boolean: a name like that needs quotes
        quote = " (in quotes when it looks like a number or boolean)" if isinstance(v, (int, float)) else ""
        raise InputError(where, f"{what} is {_type_name(v)}", f"{what}: {NAME_ALLOWED}{quote}")
    return v


def check_vector(v, where: Mark, what: str, n: int | None = None, lo=None, hi=None,
                 lo_open=False, min_len: int = 0) -> tuple:
    if not isinstance(v, list):
        size = f"{n} numbers" if n else "numbers"
        raise InputError(where, f"{what} is {_type_name(v)}", f"{what} must be a list of {size}")
    if n is not None and len(v) != n:
        raise InputError(where, f"{what} has {len(v)} values", f"{what} must have exactly {n}")
    if len(v) < min_len:
        raise InputError(where, f"{what} has {len(v)} values", f"{what} must have at least {min_len}")
    marks = getattr(v, "item_marks", None)
    out = []
    for i, x in enumerate(v):
        m = marks[i] if marks and i < len(marks) else where
        out.append(float(check_number(x, m, f"{what}[{i}]", lo, hi, lo_open)))
    return tuple(out)


class Fields:
    """Read one YAML mapping against a schema; unknown keys are errors (see the module doc)."""

    def __init__(self, value, where: Mark, what: str, keys: Sequence[str] | None = None):
        if not isinstance(value, dict):
            raise InputError(mark_of(value, where), f"{what} is {_type_name(value)}", f"{what} must be a mapping")
        self.m: YMap = value
        self.where = getattr(value, "mark", where)
        self.what = what
        self.known: list[str] = []
        self.schema = None if keys is None else list(keys)
        if self.schema is not None:
            self._refuse_unknown(self.schema)

    # positions ---------------------------------------------------------------------------
    def vmark(self, key) -> Mark:
        return self.m.value_mark(key) if isinstance(self.m, YMap) else self.where

    def kmark(self, key) -> Mark:
        return self.m.key_mark(key) if isinstance(self.m, YMap) else self.where

    # access --------------------------------------------------------------------------------
    def has(self, key: str) -> bool:
        self._know(key)
        return key in self.m

    def _know(self, key):
        if self.schema is not None and key not in self.schema:
            raise KeyError(f"{key!r} is not in the schema of {self.what}")  # a bug, not bad input
        if key not in self.known:
            self.known.append(key)

    def raw(self, key: str, required: bool = False, default=None):
        self._know(key)
        if key not in self.m:
            if required:
                # a misspelt key is reported as unknown (with its position), not as a missing one
                unread = [k for k in self.m if k not in self.known and k not in (self.schema or ())]
                near = nearest(key, unread)
                if near is not None:
                    raise InputError(self.kmark(near), f"unknown key {near!r} in {self.what}",
                                     f"did you mean {key!r}? {self.what} needs {key!r}")
                raise InputError(self.where, f"{self.what} has no {key!r}", f"{self.what} needs {key!r}")
            return default
        return self.m[key]

    def number(self, key, default=None, required=False, lo=None, hi=None, lo_open=False, integer=False):
        v = self.raw(key, required, None)
        if v is None and key not in self.m:
            return default
        return check_number(v, self.vmark(key), key, lo, hi, lo_open, integer)

    def boolean(self, key, default=None, required=False) -> bool:
        v = self.raw(key, required, None)
        if key not in self.m:
            return default
        if not isinstance(v, bool):
            raise InputError(self.vmark(key), f"{key} is {_type_name(v)}", f"{key} must be true or false")
        return v

    def name(self, key, default=None, required=False) -> str:
        v = self.raw(key, required, None)
        if key not in self.m:
            return default
        return check_name(v, self.vmark(key), key)

    def string(self, key, default=None, required=False) -> str:
        v = self.raw(key, required, None)
        if key not in self.m:
            return default
        if not isinstance(v, str) or not v:
            raise InputError(self.vmark(key), f"{key} is {_type_name(v)}", f"{key} must be a non-empty string")
        return v

    def choice(self, key, choices: Sequence[str], default=None, required=False) -> str:
        v = self.raw(key, required, None)
        if key not in self.m:
            return default
        if v not in choices:
            raise InputError(self.vmark(key), f"{key} is {_type_name(v)}",
                             f"{key} is one of {', '.join(choices)}")
        return v

    def vector(self, key, n=None, default=None, required=False, lo=None, hi=None, lo_open=False,
               min_len: int = 0):
        v = self.raw(key, required, None)
        if key not in self.m:
            return default
        return check_vector(v, self.vmark(key), key, n, lo, hi, lo_open, min_len)

    def seq(self, key, default=None, required=False, min_len: int = 0) -> YSeq | None:
        v = self.raw(key, required, None)
        if key not in self.m:
            return default
        if not isinstance(v, list):
            raise InputError(self.vmark(key), f"{key} is {_type_name(v)}", f"{key} must be a list")
        if len(v) < min_len:
            raise InputError(self.vmark(key), f"{key} has {len(v)} entries",
                             f"{key} needs at least {min_len}")
        return v

    def mapping(self, key, default=None, required=False) -> YMap | None:
        v = self.raw(key, required, None)
        if key not in self.m:
            return default
        if not isinstance(v, dict):
            raise InputError(self.vmark(key), f"{key} is {_type_name(v)}", f"{key} must be a mapping")
        return v

    def done(self, extra_allowed: Iterable[str] = ()) -> None:
        self._refuse_unknown(list(self.known) + [k for k in extra_allowed if k not in self.known])

    def _refuse_unknown(self, allowed: list) -> None:
        for key in self.m:
            if key not in allowed:
                raise InputError(self.kmark(key), f"unknown key {key!r} in {self.what}",
                                 f"{did_you_mean(key, allowed)}allowed: {', '.join(allowed)}")


def item_marks(seq, where: Mark) -> list[Mark]:
    marks = getattr(seq, "item_marks", None)
    if marks is None:
        return [where] * len(seq)
    return marks
