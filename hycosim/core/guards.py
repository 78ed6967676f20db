"""Event guards: the paper's h_B(s_B) = C, written as small expressions over node outputs.

A guard reads outputs as ``node.port`` and may use numbers, arithmetic, comparisons,
``and``/``or``/``not`` and ``abs``/``min``/``max``. It is parsed with Python's ``ast``
and evaluated by walking that tree against a fixed whitelist, so a config file can never
run code. It is evaluated at every macro-step point, so nothing in it may take long: its
text and nesting are bounded, and ``**`` is a float power (``9**9**9`` on ints would compute
for hours; as floats it overflows at once).
"""

from __future__ import annotations

import ast
import math
import operator
from typing import Any, Mapping

MAX_TEXT = 1000  # characters: a guard is a short expression over a few ports
MAX_DEPTH = 64  # levels of the expression's tree: Python's parser and _check recurse per level

_BINARY = {
    ast.Add: operator.add,
    ast.Sub: operator.sub,
    ast.Mult: operator.mul,
    ast.Div: operator.truediv,
    ast.Mod: operator.mod,
    ast.Pow: math.pow,  # float: an int power of ints may take hours (see above)
}
_UNARY = {ast.USub: operator.neg, ast.UAdd: operator.pos, ast.Not: operator.not_}
_COMPARE = {
    ast.Lt: operator.lt,
    ast.LtE: operator.le,
    ast.Gt: operator.gt,
    ast.GtE: operator.ge,
    ast.Eq: operator.eq,
    ast.NotEq: operator.ne,
}
_FUNCTIONS = {"abs": abs, "min": min, "max": max}
_ARGUMENTS = {"abs": (1, 1), "min": (2, 32), "max": (2, 32)}  # min(x) would iterate over x


class GuardError(ValueError):
    """A guard expression that does not parse or uses something not allowed."""


class Guard:
    """A compiled guard expression; call :meth:`holds` with current output values."""

    def __init__(self, text: str):
        self.text = text
        if len(text) > MAX_TEXT:
            raise GuardError(f"guard {text[:40]!r}… is {len(text)} characters; a guard has at most {MAX_TEXT}")
        if not text.isascii():
            # Node and port names are ASCII, and Python's parser folds other letters to ASCII ones
            # (NFKC): 'rod.ａngle' would be read as rod.angle, unlike what it says.
            first = next(c for c in text if not c.isascii())
            raise GuardError(f"guard {text!r} holds {first!r} (U+{ord(first):04X}): a guard is ASCII, as node and "
                             "port names are")
        try:
            tree = ast.parse(text, mode="eval")
        except SyntaxError as exc:
            raise GuardError(f"guard {text!r} does not parse: {exc.msg}") from None
        except (ValueError, RecursionError, MemoryError) as exc:  # NUL bytes; nesting the parser gives up on
            raise GuardError(f"guard {text!r} does not parse: {exc or 'nested too deeply'}") from None
        self._tree = tree.body
        self.references: list[tuple[str, str]] = []
        self._check(self._tree, 1)

    def _check(self, node: ast.AST, depth: int) -> None:
        if depth > MAX_DEPTH:
            raise GuardError(f"guard {self.text!r} nests deeper than {MAX_DEPTH} levels")
        depth += 1
        if isinstance(node, ast.Attribute):
            if not isinstance(node.value, ast.Name):
                raise GuardError(f"guard {self.text!r}: write ports as node.port")
            ref = (node.value.id, node.attr)
            if ref not in self.references:
                self.references.append(ref)
        elif isinstance(node, ast.Constant):
            if not isinstance(node.value, (int, float, bool)):
                raise GuardError(f"guard {self.text!r}: only numbers and booleans are allowed as constants")
        elif isinstance(node, ast.BinOp) and type(node.op) in _BINARY:
            self._check(node.left, depth)
            self._check(node.right, depth)
        elif isinstance(node, ast.UnaryOp) and type(node.op) in _UNARY:
            self._check(node.operand, depth)
        elif isinstance(node, ast.BoolOp):
            for v in node.values:
                self._check(v, depth)
        elif isinstance(node, ast.Compare) and all(type(op) in _COMPARE for op in node.ops):
            self._check(node.left, depth)
            for c in node.comparators:
                self._check(c, depth)
        elif (isinstance(node, ast.Call) and isinstance(node.func, ast.Name)
              and node.func.id in _FUNCTIONS and not node.keywords):
            least, most = _ARGUMENTS[node.func.id]
            if not least <= len(node.args) <= most:
                raise GuardError(f"guard {self.text!r}: {node.func.id} takes "
                                 + (f"{least} argument" if least == most else f"{least} to {most} arguments"))
            for a in node.args:
                self._check(a, depth)
        elif isinstance(node, ast.Name):
            raise GuardError(f"guard {self.text!r}: bare name {node.id!r}; write ports as node.port")
        else:
            raise GuardError(f"guard {self.text!r}: {type(node).__name__} is not allowed")

    def evaluate(self, values: Mapping[tuple[str, str], Any]) -> Any:
        """The guard's value on ``values`` (each referenced port's value by (node, port))."""
        return self._eval(self._tree, values)

    def holds(self, values: Mapping[tuple[str, str], Any]) -> bool:
        """Whether the guard holds on ``values`` (its value, taken as a truth value)."""
        return bool(self.evaluate(values))

    def inputs(self, values: Mapping[tuple[str, str], Any]) -> dict[str, Any]:
        """The referenced values, keyed 'node.port', for the events log."""
        return {f"{n}.{p}": values.get((n, p)) for n, p in self.references}

    def _eval(self, node: ast.AST, values: Mapping[tuple[str, str], Any]) -> Any:
        if isinstance(node, ast.Attribute):
            return values[(node.value.id, node.attr)]  # type: ignore[union-attr]
        if isinstance(node, ast.Constant):
            return node.value
        if isinstance(node, ast.BinOp):
            return _BINARY[type(node.op)](self._eval(node.left, values), self._eval(node.right, values))
        if isinstance(node, ast.UnaryOp):
            return _UNARY[type(node.op)](self._eval(node.operand, values))
        if isinstance(node, ast.BoolOp):
            results = (self._eval(v, values) for v in node.values)
            return all(results) if isinstance(node.op, ast.And) else any(results)
        if isinstance(node, ast.Compare):
            left = self._eval(node.left, values)
            for op, comp in zip(node.ops, node.comparators):
                right = self._eval(comp, values)
                if not _COMPARE[type(op)](left, right):
                    return False
                left = right
            return True
        if isinstance(node, ast.Call):
            return _FUNCTIONS[node.func.id](*(self._eval(a, values) for a in node.args))  # type: ignore[union-attr]
        raise GuardError(f"guard {self.text!r}: cannot evaluate {type(node).__name__}")
