"""What GenApi nodes mean: values, writes, limits and access modes, evaluated through pointers.

:class:`Evaluator` answers for any node of a :class:`~wavestack.drivers.genicam.document.Document`:
its value (following ``pValue``, ``pIndex``, formulas and converters down to registers), a write
(back up the same chain, converters applying ``FormulaTo``), ``Min``/``Max``/``Inc`` (constants
or pointers, else what the node below allows) and its access mode (``pIsImplemented``,
``pIsAvailable``, ``pIsLocked``, ``ImposedAccessMode`` over the register's ``AccessMode``).
Registers are read and written through the attached ports, with their addresses worked out on
every access (``Address`` + ``pAddress`` + inline ``IntSwissKnife`` terms + ``pIndex`` times its
offset), so a selector's value moves them; their bytes go through a
:class:`~wavestack.drivers.genicam.registers.RegisterCache`, and a write drops every cached node
that names a written node in its ``pInvalidator``.

Every evaluation walks a chain of at most :data:`MAX_CHAIN` nodes and refuses to enter a node it
is already inside, so pointer loops in a hostile file end in :class:`GenApiError`, never in a
hang or a blown stack.

Reference: EMVA GenICam Standard, GenApi (node types, "Access mode", "Caching", "Selectors").
"""

from __future__ import annotations

import math
import struct
from collections.abc import Iterator
from contextlib import contextmanager

from wavestack.drivers.genicam.document import Document, Node
from wavestack.drivers.genicam.formula import FormulaError, Tree, evaluate, parse_formula
from wavestack.drivers.genicam.registers import (BitField, Cachable, Endianness, Port, RegisterCache, bit_field,
                                                 decode_integer, encode_integer, integer_range)

MAX_CHAIN = 64
MAX_REGISTER_BYTES = 1 << 20
INT64_MIN, INT64_MAX = -(1 << 63), (1 << 63) - 1
REGISTER_TAGS = frozenset({"IntReg", "MaskedIntReg", "FloatReg", "StringReg", "Register"})
KINDS = {"Integer": "integer", "IntReg": "integer", "MaskedIntReg": "integer", "IntSwissKnife": "integer",
         "IntConverter": "integer", "Float": "float", "FloatReg": "float", "SwissKnife": "float",
         "Converter": "float", "Boolean": "boolean", "Enumeration": "enumeration", "Command": "command",
         "String": "string", "StringReg": "string", "Register": "register", "Category": "category", "Port": "port"}
Value = int | float | bool | str | bytes


class GenApiError(Exception):
    """A node that cannot be evaluated as the file describes it; ``node`` names where."""

    def __init__(self, node: str, message: str) -> None:
        super().__init__(f"node {node!r}: {message}")
        self.node = node


def _int(text: str, node: str) -> int:
    try:
        return int(text, 16) if text.lower().startswith(("0x", "-0x")) else int(text, 10)
    except ValueError:
        raise GenApiError(node, f"expected an integer, got {text!r}") from None


def _float(text: str, node: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise GenApiError(node, f"expected a number, got {text!r}") from None
    if not math.isfinite(value):
        raise GenApiError(node, f"expected a finite number, got {text!r}")
    return value


def _meet(a: str, b: str) -> str:
    """The access both modes allow (RW with RO is RO; RO with WO is NA)."""
    if a in ("NI", "NA") or b in ("NI", "NA"):
        return a if a in ("NI", "NA") else b
    rights = {"RW": {"R", "W"}, "RO": {"R"}, "WO": {"W"}}
    both = rights.get(a, set()) & rights.get(b, set())
    return "RW" if both == {"R", "W"} else "RO" if both == {"R"} else "WO" if both == {"W"} else "NA"


class Evaluator:
    """Evaluates the nodes of one document against the attached ports (not thread-safe: the node map locks).

    Parameters
    ----------
    document
        The device's nodes.
    """

    def __init__(self, document: Document) -> None:
        self._doc = document
        self._ports: dict[str, Port] = {}
        self._cache = RegisterCache()
        self._local: dict[str, Value] = {}
        self._active: list[str] = []
        self._formulas: dict[tuple[str, str], Tree] = {}
        self._written: list[str] = []
        self._dependents: dict[str, set[str]] = {}
        for node in document.nodes.values():
            for element in node.all("pInvalidator"):
                self._dependents.setdefault(element.text, set()).add(node.name)

    # --- structure -------------------------------------------------------------------------------
    def attach(self, port: Port, name: str) -> None:
        self._ports[name] = port
        self._cache.clear()

    def forget_cache(self) -> None:
        self._cache.clear()

    def node(self, name: str) -> Node:
        if name in self._doc.duplicates:
            raise GenApiError(name, "is defined more than once in the XML")
        node = self._doc.nodes.get(name)
        if node is None:
            raise GenApiError(name, "is referenced but not defined in the XML")
        return node

    def kind(self, name: str) -> str:
        return KINDS.get(self.node(name).tag, "unsupported")

    @contextmanager
    def _enter(self, name: str) -> Iterator[Node]:
        if name in self._active:
            loop = " -> ".join(self._active[self._active.index(name):] + [name])
            raise GenApiError(name, f"pointer loop {loop}")
        if len(self._active) >= MAX_CHAIN:
            raise GenApiError(name, f"chain of more than {MAX_CHAIN} nodes")
        node = self.node(name)
        self._active.append(name)
        try:
            yield node
        finally:
            self._active.pop()

    def _formula(self, node: Node, tag: str) -> Tree:
        key = (node.name, tag)
        if key not in self._formulas:
            text = node.text(tag)
            if text is None:
                raise GenApiError(node.name, f"lacks <{tag}>")
            try:
                self._formulas[key] = parse_formula(text)
            except FormulaError as exc:
                raise GenApiError(node.name, f"<{tag}>: {exc}") from None
        return self._formulas[key]

    def _compute(self, node: Node, tag: str, extra: dict[str, int | float]) -> int | float:
        variables = {e.attributes.get("Name", ""): e.text for e in node.all("pVariable")}
        constants = {e.attributes.get("Name", ""): e.text for e in node.all("Constant")}
        expressions = {e.attributes.get("Name", ""): e.text for e in node.all("Expression")}
        expanding: list[str] = []

        def lookup(variable: str) -> int | float:
            if variable in extra:
                return extra[variable]
            if variable in variables:
                return self.numeric(variables[variable])
            if variable in constants:
                return _float(constants[variable], node.name)
            if variable in expressions:
                if variable in expanding:
                    raise FormulaError(f"expression {variable} refers to itself")
                expanding.append(variable)
                try:
                    return evaluate(parse_formula(expressions[variable]), lookup, integer=node.tag.startswith("Int"))
                finally:
                    expanding.pop()
            raise FormulaError(f"variable {variable!r} is not defined by a pVariable")

        try:
            return evaluate(self._formula(node, tag), lookup, integer=node.tag.startswith("Int"))
        except FormulaError as exc:
            raise GenApiError(node.name, f"<{tag}>: {exc}") from None

    # --- values ----------------------------------------------------------------------------------
    def numeric(self, name: str) -> int | float:
        """A node's value as a number (enumerations their integer, booleans 0/1), for formulas and pointers."""
        value = self.value(name)
        if isinstance(value, bool):
            return int(value)
        if not isinstance(value, (int, float)):
            raise GenApiError(name, f"is used as a number but holds {type(value).__name__}")
        return value

    def value(self, name: str) -> Value:
        with self._enter(name) as node:
            tag = node.tag
            if tag in REGISTER_TAGS:
                return self._register_value(node)
            if tag in ("SwissKnife", "IntSwissKnife"):
                return self._compute(node, "Formula", {})
            if tag in ("Converter", "IntConverter"):
                return self._compute(node, "FormulaFrom", {"TO": self.numeric(self._pointer(node, "pValue"))})
            if tag in ("Integer", "Float", "Boolean", "Enumeration", "Command", "String"):
                raw = self._stored(node)
                if tag == "Boolean":
                    on, off = self._on_off(node)
                    if raw not in (on, off):
                        raise GenApiError(name, f"holds {raw!r}, neither OnValue {on} nor OffValue {off}")
                    return raw == on
                if tag == "Float" and isinstance(raw, int):
                    return float(raw)
                return raw
            raise GenApiError(name, f"a {tag} node has no value")

    def _pointer(self, node: Node, tag: str) -> str:
        target = node.text(tag)
        if not target:
            raise GenApiError(node.name, f"lacks <{tag}>")
        return target

    def _stored(self, node: Node) -> Value:
        """The value of a node that holds one (Value/pValue/pIndex): the value nodes' common ground."""
        if node.all("pIndex"):
            index = self.numeric(node.text("pIndex") or "")
            for tag in ("pValueIndexed", "ValueIndexed"):
                for element in node.all(tag):
                    if _int(element.attributes.get("Index", ""), node.name) == index:
                        return self.value(element.text) if tag[0] == "p" else self._constant(node, element.text)
            if node.text("pValueDefault"):
                return self.value(node.text("pValueDefault") or "")
            if node.text("ValueDefault") is not None:
                return self._constant(node, node.text("ValueDefault") or "")
            raise GenApiError(node.name, f"no value for index {index}")
        if node.text("pValue"):
            return self.value(node.text("pValue") or "")
        if node.name in self._local:
            return self._local[node.name]
        if node.text("Value") is not None:
            return self._constant(node, node.text("Value") or "")
        raise GenApiError(node.name, "has neither <pValue> nor <Value>")

    def _constant(self, node: Node, text: str) -> Value:
        if node.tag == "String":
            return text
        return _float(text, node.name) if node.tag == "Float" else _int(text, node.name)

    def _on_off(self, node: Node) -> tuple[int, int]:
        return _int(node.text("OnValue", "1") or "1", node.name), _int(node.text("OffValue", "0") or "0", node.name)

    # --- registers -------------------------------------------------------------------------------
    def _location(self, node: Node) -> tuple[str, int, int]:
        address = sum(_int(e.text, node.name) for e in node.all("Address"))
        address += sum(int(self.numeric(e.text)) for e in node.all("pAddress"))
        address += sum(int(self.numeric(e.text)) for e in node.all("IntSwissKnife"))
        for element in node.all("pIndex"):
            offset_text, offset_pointer = element.attributes.get("Offset"), element.attributes.get("pOffset")
            offset = int(self.numeric(offset_pointer)) if offset_pointer else _int(offset_text or "1", node.name)
            address += int(self.numeric(element.text)) * offset
        length = int(self.numeric(node.text("pLength") or "")) if node.text("pLength") else \
            _int(node.text("Length", "") or "", node.name)
        if not 0 <= address < 1 << 64:
            raise GenApiError(node.name, f"address {address} is not a u64")
        limit = 8 if node.tag in ("IntReg", "MaskedIntReg") else MAX_REGISTER_BYTES
        if not 1 <= length <= limit or (node.tag == "FloatReg" and length not in (4, 8)):
            raise GenApiError(node.name, f"length {length} B does not suit a {node.tag}")
        port = node.text("pPort", "Device") or "Device"
        if port not in self._ports:
            raise GenApiError(node.name, f"port {port!r} is not attached")
        return port, address, length

    def _layout(self, node: Node, length: int) -> tuple[Endianness, bool, BitField | None]:
        endianness = node.text("Endianess", "LittleEndian")
        if endianness not in ("LittleEndian", "BigEndian"):
            raise GenApiError(node.name, f"Endianess {endianness!r}; expected LittleEndian or BigEndian")
        signed = node.text("Sign", "Unsigned") == "Signed"
        field = None
        if node.tag == "MaskedIntReg":
            bit = node.text("Bit")
            lsb = _int(bit if bit is not None else node.text("LSB", "") or "", node.name)
            msb = _int(bit if bit is not None else node.text("MSB", "") or "", node.name)
            try:
                field = bit_field(lsb, msb, length, endianness)  # type: ignore[arg-type]
            except ValueError as exc:
                raise GenApiError(node.name, str(exc)) from None
        return endianness, signed, field  # type: ignore[return-value]

    def _policy(self, node: Node) -> Cachable:
        policy = node.text("Cachable", "WriteThrough")
        if policy not in ("NoCache", "WriteThrough", "WriteAround"):
            raise GenApiError(node.name, f"Cachable {policy!r}; expected NoCache, WriteThrough or WriteAround")
        return policy  # type: ignore[return-value]

    def _read_bytes(self, node: Node) -> tuple[bytes, int]:
        if node.text("AccessMode", "RO") == "WO":
            raise GenApiError(node.name, "is write-only")
        port, address, length = self._location(node)
        data = self._cache.read(node.name, port, address, length, self._policy(node),
                                lambda: self._ports[port].read(address, length))
        if len(data) != length:
            raise GenApiError(node.name, f"port returned {len(data)} B for a {length}-byte register")
        return data, length

    def _register_value(self, node: Node) -> Value:
        data, length = self._read_bytes(node)
        if node.tag in ("IntReg", "MaskedIntReg"):
            endianness, signed, field = self._layout(node, length)
            return decode_integer(data, endianness, signed, field)
        if node.tag == "FloatReg":
            big = node.text("Endianess", "LittleEndian") == "BigEndian"
            return float(struct.unpack((">" if big else "<") + ("f" if length == 4 else "d"), data)[0])
        if node.tag == "StringReg":
            return data.split(b"\0", 1)[0].decode("ascii", "replace")
        return data

    def _write_register(self, node: Node, value: Value) -> None:
        if node.text("AccessMode", "RO") == "RO":
            raise GenApiError(node.name, "is read-only")
        port, address, length = self._location(node)
        try:
            if node.tag in ("IntReg", "MaskedIntReg"):
                endianness, signed, field = self._layout(node, length)
                old = self._read_bytes(node)[0] if field is not None else None
                data = encode_integer(int(value), length, endianness, signed, field, old)
            elif node.tag == "FloatReg":
                big = node.text("Endianess", "LittleEndian") == "BigEndian"
                data = struct.pack((">" if big else "<") + ("f" if length == 4 else "d"), float(value))
            elif node.tag == "StringReg":
                text = str(value).encode("ascii") if str(value).isascii() else b"\0"
                if len(text) > length or b"\0" in text:
                    raise ValueError(f"expected ASCII text of at most {length} characters, got {value!r}")
                data = text.ljust(length, b"\0")
            else:
                data = bytes(value) if isinstance(value, (bytes, bytearray)) else b""
                if len(data) != length:
                    raise ValueError(f"expected {length} bytes")
        except (ValueError, OverflowError, struct.error) as exc:
            raise GenApiError(node.name, str(exc)) from None
        self._ports[port].write(address, data)
        self._cache.wrote(node.name, port, address, data, self._policy(node))

    # --- writes ----------------------------------------------------------------------------------
    def set_value(self, name: str, value: Value) -> None:
        """Write ``value`` through ``name``'s chain; afterwards every cached node the chain invalidates is dropped."""
        self._written = []
        try:
            self._set(name, value)
        finally:
            stale: set[str] = set()
            stack = list(self._written)
            while stack:
                for dependent in self._dependents.get(stack.pop(), ()):
                    if dependent not in stale:
                        stale.add(dependent)
                        stack.append(dependent)
            self._cache.forget(stale)

    def _set(self, name: str, value: Value) -> None:
        with self._enter(name) as node:
            self._written.append(name)
            tag = node.tag
            if tag in REGISTER_TAGS:
                self._write_register(node, value)
            elif tag in ("Converter", "IntConverter"):
                target = self._pointer(node, "pValue")
                raw = self._compute(node, "FormulaTo", {"FROM": value})  # type: ignore[dict-item]
                self._set(target, round(raw) if self.kind(target) in ("integer", "enumeration") else raw)
            elif tag in ("Integer", "Float", "Boolean", "Enumeration", "Command", "String"):
                if tag == "Boolean":
                    on, off = self._on_off(node)
                    value = on if value else off
                if node.text("pValue"):
                    self._set(node.text("pValue") or "", value)
                elif node.all("pIndex"):
                    raise GenApiError(name, "indexed values are read-only here")
                elif node.text("Value") is not None:
                    self._local[name] = value
                else:
                    raise GenApiError(name, "has neither <pValue> nor <Value>")
            else:
                raise GenApiError(name, f"a {tag} node cannot be written")

    def execute(self, name: str) -> None:
        """Execute a Command: write its command value (the register is self-clearing: nothing is cached)."""
        node = self.node(name)
        if node.tag != "Command":
            raise GenApiError(name, f"is a {node.tag}, not a Command")
        command = self.numeric(node.text("pCommandValue") or "") if node.text("pCommandValue") else \
            _int(node.text("CommandValue", "") or "", name)
        self.set_value(name, command)
        self._cache.forget(set(self._written))

    # --- limits ----------------------------------------------------------------------------------
    def limit(self, name: str, which: str) -> int | float | None:
        """``Min``, ``Max`` or ``Inc`` of a numeric node (None: no increment)."""
        with self._enter(name) as node:
            tag = node.tag
            if node.text(which) is not None:
                return _float(node.text(which) or "", name) if tag == "Float" else _int(node.text(which) or "", name)
            if node.text("p" + which):
                return self.numeric(node.text("p" + which) or "")
            if tag in ("Integer", "Float") and node.text("pValue"):
                return self.limit(node.text("pValue") or "", which)
            if tag in ("Converter", "IntConverter"):
                return self._converted_limit(node, which)
            if tag in ("IntReg", "MaskedIntReg") and which != "Inc":
                _, _, length = self._location(node)
                _, signed, field = self._layout(node, length)
                return integer_range(length, signed, field)[0 if which == "Min" else 1]
            if which == "Inc":
                return 1 if KINDS.get(tag) == "integer" else None
            if KINDS.get(tag) == "integer":
                return INT64_MIN if which == "Min" else INT64_MAX
            return -1.7976931348623157e308 if which == "Min" else 1.7976931348623157e308

    def _converted_limit(self, node: Node, which: str) -> int | float | None:
        if which == "Inc":
            return None
        target = self._pointer(node, "pValue")
        ends = [self._compute(node, "FormulaFrom", {"TO": bound}) for bound in
                (self.limit(target, "Min"), self.limit(target, "Max")) if bound is not None]
        return min(ends) if which == "Min" else max(ends)

    # --- access ----------------------------------------------------------------------------------
    def access(self, name: str) -> str:
        """``NI`` (not implemented), ``NA`` (not available), ``RO``, ``WO`` or ``RW``, now."""
        with self._enter(name) as node:
            if node.text("pIsImplemented") and not self.numeric(node.text("pIsImplemented") or ""):
                return "NI"
            if node.text("pIsAvailable") and not self.numeric(node.text("pIsAvailable") or ""):
                return "NA"
            tag = node.tag
            if tag in REGISTER_TAGS:
                mode = node.text("AccessMode", "RO") or "RO"
            elif tag in ("SwissKnife", "IntSwissKnife"):
                mode = "RO"
            elif node.text("pValue"):
                mode = self.access(node.text("pValue") or "")
            elif tag == "Category" or tag == "Port":
                mode = "RO"
            else:
                mode = "RO" if node.all("pIndex") else "RW"
            if node.text("ImposedAccessMode"):
                mode = _meet(mode, node.text("ImposedAccessMode") or "RW")
            if mode in ("RW", "WO") and node.text("pIsLocked") and self.numeric(node.text("pIsLocked") or ""):
                mode = "RO" if mode == "RW" else "NA"
            return mode

    def entries(self, name: str) -> dict[str, int]:
        """An enumeration's entries that are implemented and available now: name -> value."""
        node = self.node(name)
        found: dict[str, int] = {}
        for entry in node.entries:
            if entry.text("pIsImplemented") and not self.numeric(entry.text("pIsImplemented") or ""):
                continue
            if entry.text("pIsAvailable") and not self.numeric(entry.text("pIsAvailable") or ""):
                continue
            found[entry.name] = _int(entry.text("Value", "") or "", entry.name)
        return found
