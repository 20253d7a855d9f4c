"""GenICam GenApi: a device's features evaluated from its own XML, for every transport.

The face is :class:`NodeMap` (also re-exported by :mod:`wavestack.drivers`): built from the XML
bytes (:meth:`NodeMap.from_xml`), a register :class:`Port` attached later by the transport (USB3
Vision GenCP, GigE Vision GVCP), ``name in node_map`` when a feature resolves through the nodes.
Pure modules, no I/O of their own:

* :mod:`~wavestack.drivers.genicam.document` -- the XML read safely into named nodes.
* :mod:`~wavestack.drivers.genicam.formula` -- the SwissKnife formula language (a parser, no eval).
* :mod:`~wavestack.drivers.genicam.registers` -- register layouts (endianness, sign, bit fields), the cache.
* :mod:`~wavestack.drivers.genicam.evaluator` -- what each node type means (values, writes, limits, access).
* :mod:`~wavestack.drivers.genicam.camera_features` -- the station's camera features on any node map.

Every node type and reference real camera XML uses is evaluated: Integer, Float, Boolean,
Enumeration, Command, String; IntReg, MaskedIntReg, FloatReg, StringReg, StructReg, Register;
Converter, IntConverter, SwissKnife, IntSwissKnife; pAddress, pIndex, pIsImplemented, pIsAvailable,
pIsLocked, ImposedAccessMode, pInvalidator and register caching; Min/Max/Inc through pointers.
Presentation elements (tooltips, categories' display) are read past.

Reference: EMVA GenICam Standard, GenApi module, schema 1.0 and 1.1; SFNC 2.x for feature names.
"""

from __future__ import annotations

from wavestack.drivers.genicam.document import extract_xml
from wavestack.drivers.genicam.formula import FormulaError, evaluate, parse_formula
from wavestack.drivers.genicam.node_map import FeatureInfo, NodeMap
from wavestack.drivers.genicam.registers import Port

__all__ = ["FeatureInfo", "FormulaError", "NodeMap", "Port", "evaluate", "extract_xml", "parse_formula"]
