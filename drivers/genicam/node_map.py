"""The GenICam node map: a device's features, evaluated from its own GenApi XML through a port.

:class:`NodeMap` is built from the XML bytes alone (:meth:`NodeMap.from_xml`), so the XML can be
checked and inspected without a device; a transport attaches its register port later
(:meth:`NodeMap.attach`: a USB3 Vision GenCP channel, a GigE Vision GVCP channel, a simulator).
The public verbs validate first (access mode now, range, increment, enumeration entries) and
only then write, so a refused value sends nothing. Errors name the device and the feature: a
structural problem (a missing node, a loop, a formula dividing by zero) is a ``ProtocolError``, a
value outside the device's limits a ``LimitError``, and the port's own errors (timeouts, refusals,
disconnection) pass through unchanged.

Example
-------
>>> xml = b'''<RegisterDescription xmlns="http://www.genicam.org/GenApi/Version_1_1">
...   <Integer Name="Width"><pValue>WidthReg</pValue><Min>16</Min><Max>4096</Max><Inc>16</Inc></Integer>
...   <IntReg Name="WidthReg"><Address>0x100</Address><Length>4</Length><AccessMode>RW</AccessMode>
...     <pPort>Device</pPort><Endianess>BigEndian</Endianess></IntReg>
...   <Port Name="Device"/></RegisterDescription>'''
>>> node_map = NodeMap.from_xml(xml, device="demo camera")
>>> "Width" in node_map, "Height" in node_map
(True, False)
>>> memory = bytearray(0x200)
>>> class Memory:
...     def read(self, address, length): return bytes(memory[address:address + length])
...     def write(self, address, data): memory[address:address + len(data)] = data
>>> node_map.attach(Memory())
>>> node_map.set("Width", 1024)
>>> node_map.get("Width"), bytes(memory[0x100:0x104])
(1024, b'\\x00\\x00\\x04\\x00')
"""

from __future__ import annotations

import math
import threading
from collections.abc import Iterator, Mapping
from contextlib import contextmanager
from dataclasses import dataclass, field
from types import MappingProxyType

from wavestack.drivers.errors import DeviceError, LimitError, ProtocolError
from wavestack.drivers.genicam.document import Document, load_document
from wavestack.drivers.genicam.evaluator import KINDS, Evaluator, GenApiError, Value
from wavestack.drivers.genicam.formula import FormulaError, parse_formula, variables
from wavestack.drivers.genicam.registers import Port

_POINTERS = ("pValue", "pAddress", "pIndex", "pMin", "pMax", "pInc", "pIsImplemented", "pIsAvailable", "pIsLocked",
             "pCommandValue", "pLength", "IntSwissKnife", "pValueIndexed", "pValueDefault")
_FORMULAS = {"SwissKnife": ("Formula",), "IntSwissKnife": ("Formula",), "Converter": ("FormulaTo", "FormulaFrom"),
             "IntConverter": ("FormulaTo", "FormulaFrom")}
_FEATURE_KINDS = frozenset({"integer", "float", "boolean", "enumeration", "command", "string", "register"})


@dataclass(frozen=True)
class FeatureInfo:
    """What a feature is and allows, now.

    Attributes
    ----------
    name
        The feature.
    kind
        ``"integer"``, ``"float"``, ``"boolean"``, ``"enumeration"``, ``"command"``, ``"string"`` or
        ``"register"``.
    access
        ``"RW"``, ``"RO"``, ``"WO"``, ``"NA"`` (not available now) or ``"NI"`` (not implemented).
    minimum, maximum, increment
        Numeric features' limits (``increment`` None when a float has none); None otherwise.
    entries
        Enumerations: the entries implemented and available now, name -> value.
    unit
        ``Unit`` from the XML (e.g. ``"us"``), or None.
    """

    name: str
    kind: str
    access: str
    minimum: int | float | None = None
    maximum: int | float | None = None
    increment: int | float | None = None
    entries: Mapping[str, int] = field(default_factory=dict)
    unit: str | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "entries", MappingProxyType(dict(self.entries)))

    @property
    def readable(self) -> bool:
        return self.access in ("RO", "RW")

    @property
    def writable(self) -> bool:
        return self.access in ("WO", "RW")


class NodeMap:
    """A device's GenApi node map (see the module description). Thread-safe: one lock per map.

    Build it with :meth:`from_xml`.
    """

    def __init__(self, document: Document, device: str) -> None:
        self._document = document
        self._evaluator = Evaluator(document)
        self._lock = threading.RLock()
        self._resolved: dict[str, bool] = {}
        self.device = device

    @classmethod
    def from_xml(cls, xml: bytes, *, device: str = "GenICam device", zipped: bool | None = None) -> NodeMap:
        """The node map of a GenApi file (plain or zipped XML), checked but not yet attached to a port.

        Raises
        ------
        ProtocolError
            Malformed or hostile XML (a DTD or entities, nesting deeper than 32, over 32 MiB), or a
            root that is not a GenApi ``RegisterDescription``; the message names ``device``.
        """
        return cls(load_document(xml, device, zipped=zipped), device)

    def attach(self, port: Port, name: str = "Device") -> None:
        """Connect the register port the XML's ``pPort`` calls ``name`` (cached register values are dropped)."""
        with self._lock:
            self._evaluator.attach(port, name)

    def forget_cache(self) -> None:
        """Drop every cached register value (after the device was reset or reconnected)."""
        with self._lock:
            self._evaluator.forget_cache()

    # --- static questions ------------------------------------------------------------------------
    def __contains__(self, name: object) -> bool:
        """Whether ``name`` is a feature whose every pointer and formula variable resolves to a node (no I/O)."""
        if not isinstance(name, str):
            return False
        with self._lock:
            if name not in self._resolved:
                node = self._document.nodes.get(name)
                self._resolved[name] = (node is not None and KINDS.get(node.tag) in _FEATURE_KINDS
                                        and self._resolves(name))
            return self._resolved[name]

    def _resolves(self, name: str) -> bool:
        seen: set[str] = set()
        stack = [name]
        while stack:
            current = stack.pop()
            if current in seen:
                continue
            seen.add(current)
            node = self._document.nodes.get(current)
            if node is None or current in self._document.duplicates:
                return False
            targets = [e.text for tag in _POINTERS for e in node.all(tag)]
            targets += [e.attributes["pOffset"] for e in node.all("pIndex") if "pOffset" in e.attributes]
            for entry in node.entries:
                targets += [e.text for tag in ("pIsImplemented", "pIsAvailable") for e in entry.all(tag)]
            named = {e.attributes.get("Name", "") for tag in ("pVariable", "Constant", "Expression")
                     for e in node.all(tag)}
            targets += [e.text for e in node.all("pVariable")]
            for tag in _FORMULAS.get(node.tag, ()):
                try:
                    free = variables(parse_formula(node.text(tag) or ""))
                except FormulaError:
                    return False
                allowed = named | ({"FROM"} if tag == "FormulaTo" else {"TO"} if tag == "FormulaFrom" else set())
                if not free <= allowed:
                    return False
            stack.extend(t for t in targets if t)
        return True

    def names(self) -> tuple[str, ...]:
        """Every node name in the XML (features and the nodes behind them), sorted."""
        return tuple(sorted(self._document.nodes))

    # --- verbs -----------------------------------------------------------------------------------
    def _fail(self, name: str, error: GenApiError | str) -> ProtocolError:
        failure = ProtocolError(self.device, f"GenICam feature {name!r}: {error}")
        failure.feature = name  # type: ignore[attr-defined]
        return failure

    def _limit(self, name: str, message: str) -> LimitError:
        failure = LimitError(self.device, message)
        failure.feature = name  # type: ignore[attr-defined]
        return failure

    @contextmanager
    def _naming(self, name: str) -> Iterator[None]:
        """Errors from the evaluator become ProtocolErrors, and the port's errors name the feature."""
        try:
            yield
        except GenApiError as error:
            raise self._fail(name, error) from None
        except DeviceError as error:
            if getattr(error, "feature", None) is not None:
                raise
            named = type(error)(error.device, f"GenICam feature {name!r}: {error.detail}")
            named.feature = name  # type: ignore[attr-defined]
            try:
                raise named from None
            finally:  # no local naming the raised error: its traceback holds this frame (a cycle)
                del named

    def _feature(self, name: str) -> str:
        if name not in self:
            node = self._document.nodes.get(name)
            reason = "is not described in the device's XML" if node is None else \
                "does not resolve through the XML's nodes (a missing node, an unknown variable or a bad formula)"
            raise ProtocolError(self.device, f"GenICam feature {name!r} {reason}")
        return self._evaluator.kind(name)

    def access(self, name: str) -> str:
        """``"RW"``, ``"RO"``, ``"WO"``, ``"NA"`` or ``"NI"`` now (reads the registers behind the pointers)."""
        with self._lock:
            self._feature(name)
            with self._naming(name):
                return self._evaluator.access(name)

    def info(self, name: str) -> FeatureInfo:
        """Kind, access, limits, entries and unit of a feature, now."""
        with self._lock:
            kind = self._feature(name)
            with self._naming(name):
                access = self._evaluator.access(name)
                limits: dict[str, int | float | None] = {}
                if kind in ("integer", "float") and access not in ("NI", "NA"):
                    limits = {"minimum": self._evaluator.limit(name, "Min"),
                              "maximum": self._evaluator.limit(name, "Max"),
                              "increment": self._evaluator.limit(name, "Inc")}
                entries = self._evaluator.entries(name) if kind == "enumeration" else {}
            unit = self._document.nodes[name].text("Unit")
            return FeatureInfo(name, kind, access, entries=entries, unit=unit, **limits)  # type: ignore[arg-type]

    def get(self, name: str) -> Value:
        """The feature's value: int, float, bool, str (a string, or an enumeration's entry name) or bytes.

        Raises
        ------
        ProtocolError
            Not readable now (the message gives the access mode), or the XML cannot be evaluated.
        """
        with self._lock:
            kind = self._feature(name)
            with self._naming(name):
                access = self._evaluator.access(name)
                if access not in ("RO", "RW"):
                    raise self._fail(name, f"is not readable now (access {access})")
                value = self._evaluator.value(name)
                if kind != "enumeration":
                    return value
                for entry, number in self._evaluator.entries(name).items():
                    if number == value:
                        return entry
                raise self._fail(name, f"holds {value!r}, which is none of its entries")

    def get_int(self, name: str) -> int:
        """An integer or enumeration feature's integer value."""
        with self._lock:
            kind = self._feature(name)
            if kind not in ("integer", "enumeration", "boolean"):
                raise self._fail(name, f"is a {kind} feature, not an integer")
            with self._naming(name):
                if self._evaluator.access(name) not in ("RO", "RW"):
                    raise self._fail(name, "is not readable now")
                return int(self._evaluator.numeric(name))

    def set(self, name: str, value: Value) -> None:
        """Write a feature after checking it is writable now and ``value`` is allowed; nothing is sent otherwise.

        Integers must lie in ``Min..Max`` on the ``Inc`` grid; floats in ``Min..Max`` and finite;
        enumerations take an entry name (or its value); booleans a bool; strings ASCII text.

        Raises
        ------
        LimitError
            ``value`` outside the limits or not an entry.
        ProtocolError
            Not writable now (locked, not available, read-only), or the XML cannot be evaluated.
        """
        with self._lock:
            kind = self._feature(name)
            with self._naming(name):
                access = self._evaluator.access(name)
                if access not in ("WO", "RW"):
                    raise self._fail(name, f"is not writable now (access {access})")
                self._evaluator.set_value(name, self._checked(name, kind, value))

    def _checked(self, name: str, kind: str, value: Value) -> Value:
        if kind == "enumeration":
            entries = self._evaluator.entries(name)
            if isinstance(value, str) and value in entries:
                return entries[value]
            if isinstance(value, int) and not isinstance(value, bool) and value in entries.values():
                return value
            raise self._limit(name, f"{name} = {value!r} is not an entry; the device offers {sorted(entries)}")
        if kind == "integer":
            if isinstance(value, bool) or not isinstance(value, int):
                raise self._limit(name, f"{name} = {value!r}: expected an integer")
            low, high = self._evaluator.limit(name, "Min"), self._evaluator.limit(name, "Max")
            step = max(1, int(self._evaluator.limit(name, "Inc") or 1))
            if not (low is None or value >= low) or not (high is None or value <= high) or \
                    (low is not None and (value - int(low)) % int(step)):
                raise self._limit(name, f"{name} = {value} outside the device's {low}..{high} in steps of {step}")
            return value
        if kind == "float":
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
                raise self._limit(name, f"{name} = {value!r}: expected a finite number")
            low, high = self._evaluator.limit(name, "Min"), self._evaluator.limit(name, "Max")
            if (low is not None and value < low) or (high is not None and value > high):
                raise self._limit(name, f"{name} = {value} outside the device's {low}..{high}")
            return float(value)
        if kind == "boolean":
            if not isinstance(value, bool):
                raise self._limit(name, f"{name} = {value!r}: expected True or False")
            return value
        if kind == "command":
            raise self._fail(name, "is a command: use execute()")
        return value

    def execute(self, name: str) -> None:
        """Execute a command feature (``AcquisitionStart``, ``TriggerSoftware``, ...) if writable now."""
        with self._lock:
            kind = self._feature(name)
            if kind != "command":
                raise self._fail(name, f"is a {kind} feature, not a command")
            with self._naming(name):
                access = self._evaluator.access(name)
                if access not in ("WO", "RW"):
                    raise self._fail(name, f"cannot be executed now (access {access})")
                self._evaluator.execute(name)
