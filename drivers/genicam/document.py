"""A device's GenApi XML read safely into a table of named nodes, without I/O.

The XML comes from the device itself (a USB3 Vision manifest, a GigE Vision first URL), so it is
treated as hostile until read: at most :data:`MAX_XML_BYTES` (also after unzipping); no DTD and no
entity declaration (which rules out entity expansion and external entities in every encoding
expat decodes); elements nested at most :data:`MAX_DEPTH` deep (real files nest 3 or 4) and at
most :data:`MAX_ELEMENTS` of them. A first pass with the standard library's expat checks all of
that, with handlers that stop at the first offence, before the tree is built; the stdlib suffices
(defusedxml wraps the same parser to refuse the same declarations, and a GenApi file never needs a
DTD), and every refusal is one ``ProtocolError`` naming the device.

Nodes are the elements with a ``Name`` attribute, at the top of ``RegisterDescription``, inside
``Group`` elements, or inline in another node (an ``IntSwissKnife`` that is one term of a register's
address). A ``StructReg`` becomes one register node per ``StructEntry``: the entry's own elements
over the structure's shared ones (address, length, port, endianness).

Reference: EMVA GenICam Standard, GenApi schema 1.0/1.1 (``RegisterDescription``, ``Group``,
``StructReg``/``StructEntry``).
"""

from __future__ import annotations

import io
import xml.etree.ElementTree as ET
import zipfile
import zlib
from collections.abc import Mapping
from dataclasses import dataclass, field
from types import MappingProxyType
from xml.parsers import expat

from wavestack.drivers.errors import ProtocolError

MAX_XML_BYTES = 32 << 20  # real files are 0.7 to 1 MB; refuse zip bombs and junk
MAX_DEPTH = 32
MAX_ELEMENTS = 2_000_000
GENAPI_NAMESPACE_PREFIX = "http://www.genicam.org/GenApi/"
_PRESENTATION = frozenset({"ToolTip", "Description", "DisplayName", "Visibility", "EventID", "Extension",
                           "DocuURL", "IsDeprecated", "Streamable", "DisplayNotation", "DisplayPrecision"})


@dataclass(frozen=True)
class Element:
    """One child element of a node: its text (stripped) and attributes."""

    text: str
    attributes: Mapping[str, str] = field(default_factory=dict)


@dataclass(frozen=True)
class Node:
    """A named GenApi node: its type (``tag``) and child elements grouped by tag, in document order.

    Attributes
    ----------
    name
        The ``Name`` attribute.
    tag
        Node type: ``Integer``, ``IntReg``, ``IntSwissKnife``, ... (``StructEntry`` nodes become
        ``MaskedIntReg``).
    elements
        Child tag -> its elements; an inline child node appears as an element whose text is its name.
    entries
        ``EnumEntry`` children of an ``Enumeration``, as nodes.
    """

    name: str
    tag: str
    elements: Mapping[str, tuple[Element, ...]]
    entries: tuple[Node, ...] = ()

    def text(self, tag: str, default: str | None = None) -> str | None:
        """Text of the first ``tag`` element, or ``default``."""
        found = self.elements.get(tag)
        return found[0].text if found else default

    def all(self, tag: str) -> tuple[Element, ...]:
        """Every ``tag`` element (empty when there is none)."""
        return self.elements.get(tag, ())


@dataclass(frozen=True)
class Document:
    """The nodes of one GenApi file.

    Attributes
    ----------
    nodes
        Node name -> :class:`Node` (read-only).
    duplicates
        Names defined more than once (an error only when such a node is used).
    """

    nodes: Mapping[str, Node]
    duplicates: frozenset[str]


def extract_xml(data: bytes, device: str, *, zipped: bool | None = None) -> bytes:
    """The XML bytes of a GenICam file that is plain or a ZIP holding one ``.xml``.

    Parameters
    ----------
    data
        File contents as read from the device.
    device
        Device name for error messages.
    zipped
        ``True``/``False`` from the manifest or URL; ``None`` sniffs the ZIP signature.

    Raises
    ------
    ProtocolError
        A broken ZIP, not exactly one ``.xml`` member, or a member larger than 32 MiB.
    """
    data = bytes(data)
    if zipped is None:
        zipped = data[:4] == b"PK\x03\x04"
    if not zipped:
        return data
    try:
        with zipfile.ZipFile(io.BytesIO(data)) as archive:
            members = [info for info in archive.infolist() if info.filename.lower().endswith(".xml")]
            if len(members) != 1:
                raise ProtocolError(device, f"expected a GenICam ZIP holding exactly one .xml file, "
                                            f"found {[info.filename for info in members]}")
            member = members[0]
            if member.file_size > MAX_XML_BYTES:
                raise ProtocolError(device, f"GenICam XML {member.filename!r} is {member.file_size} B, "
                                            f"expected <= {MAX_XML_BYTES} B")
            with archive.open(member) as stream:
                xml = stream.read(MAX_XML_BYTES + 1)
    except ProtocolError:
        raise
    except (zipfile.BadZipFile, zipfile.LargeZipFile, NotImplementedError, EOFError, zlib.error, ValueError,
            OSError, KeyError, RuntimeError, OverflowError, IndexError) as exc:
        raise ProtocolError(device, f"expected a readable GenICam ZIP file: {exc}") from None
    if len(xml) > MAX_XML_BYTES:
        raise ProtocolError(device, f"GenICam XML inflates beyond {MAX_XML_BYTES} B")
    return xml


class _Refused(Exception):
    """Raised from the expat handlers at the first offence; carries the reason."""


def check_xml(xml: bytes, device: str) -> None:
    """Refuse a document that is too large, declares a DTD or entity, nests too deep or has too many
    elements, before any tree is built (one pass of expat that stops at the first offence).

    Raises
    ------
    ProtocolError
        Naming ``device`` and the offence, or expat's message for a document that is not well formed.
    """
    if len(xml) > MAX_XML_BYTES:
        raise ProtocolError(device, f"GenICam XML of {len(xml)} B; expected at most {MAX_XML_BYTES} B")
    parser = expat.ParserCreate()
    depth = count = 0

    def declaration(*_: object) -> None:
        raise _Refused("GenICam XML with a DTD or entity declarations is refused")

    def start(*_: object) -> None:
        nonlocal depth, count
        depth += 1
        count += 1
        if depth > MAX_DEPTH:
            raise _Refused(f"GenICam XML nests elements deeper than {MAX_DEPTH} levels")
        if count > MAX_ELEMENTS:
            raise _Refused(f"GenICam XML has more than {MAX_ELEMENTS} elements")

    def end(*_: object) -> None:
        nonlocal depth
        depth -= 1

    parser.StartDoctypeDeclHandler = parser.EntityDeclHandler = declaration
    parser.StartElementHandler, parser.EndElementHandler = start, end
    try:
        parser.Parse(xml, True)
    except _Refused as refused:
        raise ProtocolError(device, str(refused)) from None
    except (expat.ExpatError, ValueError, LookupError, UnicodeError) as exc:
        raise ProtocolError(device, f"expected well-formed GenICam XML: {exc}") from None


def _local(tag: object) -> str:
    return (tag if isinstance(tag, str) else "").rsplit("}", 1)[-1]


def _elements(element: ET.Element, skip: frozenset[str] = frozenset()) -> dict[str, list[Element]]:
    grouped: dict[str, list[Element]] = {}
    for child in element:
        tag = _local(child.tag)
        if tag in _PRESENTATION or tag in skip:
            continue
        text = child.get("Name") if len(child) and child.get("Name") else (child.text or "").strip()
        grouped.setdefault(tag, []).append(Element(text or "", MappingProxyType(dict(child.attrib))))
    return grouped


def _frozen(grouped: dict[str, list[Element]]) -> Mapping[str, tuple[Element, ...]]:
    return MappingProxyType({tag: tuple(found) for tag, found in grouped.items()})


class _Builder:
    def __init__(self) -> None:
        self.nodes: dict[str, Node] = {}
        self.duplicates: set[str] = set()

    def add(self, node: Node) -> None:
        if node.name in self.nodes:
            self.duplicates.add(node.name)
        self.nodes[node.name] = node

    def visit(self, parent: ET.Element) -> None:
        """Nodes among ``parent``'s children (``Group`` elements are walked; no recursion: depth <= 32)."""
        stack = [parent]
        while stack:
            for child in stack.pop():
                tag = _local(child.tag)
                if tag == "Group":
                    stack.append(child)
                elif tag == "StructReg":
                    self._struct(child)
                elif child.get("Name"):
                    self._node(child, tag)

    def _node(self, element: ET.Element, tag: str) -> None:
        entries: list[Node] = []
        for child in element:
            child_tag = _local(child.tag)
            if child_tag == "EnumEntry" and child.get("Name"):
                entries.append(Node(child.get("Name", ""), "EnumEntry", _frozen(_elements(child))))
            elif len(child) and child.get("Name"):  # an inline node, e.g. an address term
                self._node(child, child_tag)
        self.add(Node(element.get("Name", ""), tag, _frozen(_elements(element, frozenset({"EnumEntry"}))),
                      tuple(entries)))

    def _struct(self, element: ET.Element) -> None:
        shared = _elements(element, frozenset({"StructEntry"}))
        for child in element:
            if _local(child.tag) == "StructEntry" and child.get("Name"):
                merged = dict(shared)
                merged.update(_elements(child))
                self.add(Node(child.get("Name", ""), "MaskedIntReg", _frozen(merged)))
            elif len(child) and child.get("Name"):
                self._node(child, _local(child.tag))


def load_document(data: bytes, device: str, *, zipped: bool | None = None) -> Document:
    """Read a GenApi file (plain or zipped XML) into its nodes.

    Parameters
    ----------
    data
        The file as the device delivers it.
    device
        Device name for error messages.
    zipped
        From the manifest or URL; ``None`` sniffs the ZIP signature.

    Returns
    -------
    Document

    Raises
    ------
    ProtocolError
        A hostile or malformed document (see :func:`check_xml`), or a root other than a GenApi
        ``RegisterDescription``.
    """
    xml = extract_xml(data, device, zipped=zipped)
    check_xml(xml, device)
    try:
        root = ET.fromstring(xml)
    except (ET.ParseError, ValueError, LookupError, UnicodeError) as exc:
        raise ProtocolError(device, f"expected well-formed GenICam XML: {exc}") from None
    tag = root.tag if isinstance(root.tag, str) else ""
    namespace = tag[1:].split("}", 1)[0] if tag.startswith("{") else ""
    if _local(tag) != "RegisterDescription" or (namespace and not namespace.startswith(GENAPI_NAMESPACE_PREFIX)):
        raise ProtocolError(device, f"expected a GenApi <RegisterDescription> root, got {tag!r}")
    builder = _Builder()
    builder.visit(root)
    return Document(MappingProxyType(builder.nodes), frozenset(builder.duplicates))
