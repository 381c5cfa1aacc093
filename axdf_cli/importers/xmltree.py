"""A small XML element tree that remembers where each element starts (line, column).

``xml.etree`` drops positions; OpenSim errors must say ``FILE:LINE:COL``, so the tree is
built here with :mod:`xml.parsers.expat`, reading ``CurrentLineNumber`` /
``CurrentColumnNumber`` at each start tag. Malformed or truncated XML becomes an
:class:`~axdf_cli.errors.InputError` at the parser's position.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from xml.parsers import expat

from axdf_cli.errors import InputError, Mark
from axdf_cli.fileio.yamlio import read_input
from axdf_cli.tolerances import XML_MAX_DEPTH


@dataclass(eq=False)
class Node:
    tag: str
    attrib: dict
    mark: Mark
    children: list["Node"] = field(default_factory=list)
    parts: list[str] = field(default_factory=list, repr=False)

    @property
    def text(self) -> str:
        return "".join(self.parts).strip()

    @property
    def name(self) -> str | None:
        return self.attrib.get("name")

    def find(self, tag: str) -> "Node | None":
        for c in self.children:
            if c.tag == tag:
                return c
        return None

    def findall(self, tag: str) -> list["Node"]:
        return [c for c in self.children if c.tag == tag]

    def path(self, *tags: str) -> "Node | None":
        node = self
        for t in tags:
            node = node.find(t) if node is not None else None
        return node

    def iter(self):
        yield self
        for c in self.children:
            yield from c.iter()


def parse_xml(path: Path | str, display: str | None = None) -> Node:
    """Parse the XML file at ``path`` into a :class:`Node` tree (root element)."""
    path = Path(path)
    shown = display or str(path)
    data = read_input(path, shown, "an existing .osim / .vtp file")
    parser = expat.ParserCreate()
    stack: list[Node] = []
    root: list[Node] = []

    def start(tag, attrib):
        node = Node(tag, dict(attrib), Mark(shown, parser.CurrentLineNumber, parser.CurrentColumnNumber + 1))
        if len(stack) >= XML_MAX_DEPTH:
            raise InputError(node.mark, f"<{tag}> nested too deeply", f"at most {XML_MAX_DEPTH} levels of elements")
        if stack:
            stack[-1].children.append(node)
        else:
            root.append(node)
        stack.append(node)

    def end(tag):
        stack.pop()

    def chars(text):
        if stack:
            stack[-1].parts.append(text)

    parser.StartElementHandler = start
    parser.EndElementHandler = end
    parser.CharacterDataHandler = chars
    try:
        parser.Parse(data, True)
    except expat.ExpatError as e:
        raise InputError(Mark(shown, e.lineno, e.offset + 1), f"malformed XML ({expat.ErrorString(e.code)})",
                         "a well-formed XML document") from None
    if not root:
        raise InputError(Mark(shown, 1, 1), "no XML element", "a well-formed XML document")
    return root[0]
