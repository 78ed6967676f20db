"""An FMU's ports read and written every step: one C call per variable type, buffers made once.

fmpy's ``getReal(vr)`` builds two ctypes arrays, calls through a logging wrapper and makes a
list, for each call; a node reading three outputs a step did that three times. A
:class:`PortAccess` groups a node's ports by FMI type once, when the FMU is opened, and then
reads (or writes) each group with one call of the FMU's own C function on arrays kept from
step to step. The values are the ones fmpy's calls give (the same C calls, converted to
Python as fmpy converts them), and a failed call raises fmpy's ``FMICallException`` naming
the function and the status, as fmpy's wrappers do.

Where fmpy logs every FMI call (an ``fmiCallLogger`` is set), or a port's type has no fixed
size (String, Binary), :func:`port_access` gives None and the FMU's values go through fmpy's
calls one by one, as before.
"""

from __future__ import annotations

import ctypes
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, Callable

from fmpy.fmi1 import FMICallException

# FMI type → (the C function's type name, C element type, Python conversion as fmpy's calls
# give it) per interface; String and Binary have no fixed size and are left out.
_FMI2 = {"Real": ("Real", ctypes.c_double, float), "Integer": ("Integer", ctypes.c_int, int),
         "Enumeration": ("Integer", ctypes.c_int, int), "Boolean": ("Boolean", ctypes.c_int, bool)}
_FMI3 = {"Float64": ("Float64", ctypes.c_double, float), "Float32": ("Float32", ctypes.c_float, float),
         "Int8": ("Int8", ctypes.c_int8, int), "UInt8": ("UInt8", ctypes.c_uint8, int),
         "Int16": ("Int16", ctypes.c_int16, int), "UInt16": ("UInt16", ctypes.c_uint16, int),
         "Int32": ("Int32", ctypes.c_int32, int), "UInt32": ("UInt32", ctypes.c_uint32, int),
         "Int64": ("Int64", ctypes.c_int64, int), "UInt64": ("UInt64", ctypes.c_uint64, int),
         "Enumeration": ("Int64", ctypes.c_int64, int), "Boolean": ("Boolean", ctypes.c_bool, bool)}

# The C element types whose array slice gives Python values of the conversion's type.
_SLICE_GIVES = {ctypes.c_double: float, ctypes.c_float: float, ctypes.c_int: int, ctypes.c_int8: int,
                ctypes.c_uint8: int, ctypes.c_int16: int, ctypes.c_uint16: int, ctypes.c_int32: int,
                ctypes.c_uint32: int, ctypes.c_int64: int, ctypes.c_uint64: int, ctypes.c_bool: bool}

_WARNING = 1  # fmi2Warning and fmi3Warning: above it a call failed
_STATUS_FUNCTION = ctypes.CFUNCTYPE(ctypes.c_int)  # a C function's prototype: returns an int, arguments unchecked


@dataclass(frozen=True)
class Port:
    """One port as the FMU holds it: its variable's value reference and FMI type, and its
    element count for an array variable (None for a scalar)."""

    vr: int
    type: str
    size: int | None = None


@dataclass
class _Group:
    """Ports of one FMI type, read or written in one call: ``positions`` are theirs in the
    node's port order, ``slices`` where each one's elements lie in ``values``; ``args`` the
    call's arguments (the instance, the value references and their count, ``values``, and in
    FMI 3 the element count), made once."""

    function: str
    call: Callable[..., int]
    values: Any
    convert: type
    positions: list[int]
    slices: list[tuple[int, int | None]]  # (first element, size or None for a scalar)
    args: tuple[Any, ...]


class PortAccess:
    """Reads or writes a fixed list of ports (in the node's port order) with one C call per type."""

    def __init__(self, groups: list[_Group], count: int):
        self._groups = groups
        self._count = count
        # One call (so every port in order) of scalars whose C values Python reads as the type
        # they are given as (a double as a float): a read is then the buffer's slice, unconverted.
        one = groups[0] if len(groups) == 1 else None
        self._whole = one if one is not None and all(size is None for _, size in one.slices) \
            and _SLICE_GIVES.get(one.values._type_) is one.convert else None
        # A floating-point buffer takes a list of numbers in one slice assignment, each stored as
        # float() makes it (an integer type would take a float only with its own conversion).
        self._whole_write = self._whole if self._whole is not None and self._whole.convert is float else None

    def conversions(self) -> list[type]:
        """The Python type each port's value (an array's elements) is read or written as, in order."""
        types: list[Any] = [None] * self._count
        for g in self._groups:
            for position in g.positions:
                types[position] = g.convert
        return types

    def read(self) -> list[Any]:
        """Every port's value, in order: a scalar as a Python value, an array as a list."""
        whole = self._whole
        if whole is not None:
            status = whole.call(*whole.args)
            if status > _WARNING:
                raise FMICallException(function=whole.function, status=status)
            return whole.values[:]
        out: list[Any] = [None] * self._count
        for g in self._groups:
            status = g.call(*g.args)
            if status > _WARNING:
                raise FMICallException(function=g.function, status=status)
            values, convert = g.values, g.convert
            for position, (first, size) in zip(g.positions, g.slices):
                out[position] = convert(values[first]) if size is None else \
                    [convert(v) for v in values[first:first + size]]
        return out

    def write(self, values: Sequence[Any]) -> None:
        """Set every port from ``values`` (in order; an array port's value a list of its elements)."""
        whole = self._whole_write
        if whole is not None:
            whole.values[:] = values
            status = whole.call(*whole.args)
            if status > _WARNING:
                raise FMICallException(function=whole.function, status=status)
            return
        for g in self._groups:
            buffer, convert = g.values, g.convert
            for position, (first, size) in zip(g.positions, g.slices):
                value = values[position]
                if size is None:
                    buffer[first] = convert(value)
                else:
                    buffer[first:first + size] = [convert(v) for v in value]
            status = g.call(*g.args)
            if status > _WARNING:
                raise FMICallException(function=g.function, status=status)


def bare_function(dll: ctypes.CDLL, name: str) -> Callable[..., int]:
    """The library's C function ``name`` returning a C int (an FMI status), with no argument types
    declared: it takes ctypes values (a ``c_void_p`` instance, arrays, ``c_size_t``, ``c_double``)
    as they are. Through fmpy's function object, whose argument types it declared, ctypes
    checks and converts every argument on every call: 0.9 µs for a get of two Reals here,
    0.37 µs with the arguments converted once, when the buffers are made."""
    return _STATUS_FUNCTION((name, dll))


def port_access(fmu: Any, ports: Sequence[Port], fmi3: bool, setting: bool) -> PortAccess | None:
    """A :class:`PortAccess` for ``ports`` of the fmpy FMU object ``fmu`` (FMI 2 or 3, instantiated),
    reading (or with ``setting``, writing) them; None where fmpy's calls must be used instead:
    FMI calls are being logged, or a port is of a type without a fixed size (String, Binary)."""
    if getattr(fmu, "fmiCallLogger", None) is not None:
        return None
    table = _FMI3 if fmi3 else _FMI2
    if any(p.type not in table for p in ports):
        return None
    by_name: dict[str, list[int]] = {}
    for i, p in enumerate(ports):
        by_name.setdefault(table[p.type][0], []).append(i)
    prefix = "fmi3" if fmi3 else "fmi2"
    groups = []
    for name, positions in by_name.items():
        _, ctype, convert = next(table[ports[i].type] for i in positions)
        function = f"{prefix}{'Set' if setting else 'Get'}{name}"
        slices, first = [], 0
        for i in positions:
            slices.append((first, ports[i].size))
            first += ports[i].size or 1
        vrs = (ctypes.c_uint32 * len(positions))(*(ports[i].vr for i in positions))
        values = (ctype * first)()
        args = (ctypes.c_void_p(fmu.component), vrs, ctypes.c_size_t(len(positions)), values) + \
            ((ctypes.c_size_t(first),) if fmi3 else ())
        groups.append(_Group(function, bare_function(fmu.dll, function), values, convert, positions, slices, args))
    return PortAccess(groups, len(ports))
