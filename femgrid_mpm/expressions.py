"""Safe, vectorised expressions from scene files: ``"0.01*cos(pi*x/5)"``, ``"x <= 0"``.

Scene files come from other people, so an expression is never handed to
``eval``.  It is parsed with :mod:`ast`, every node is checked against a
whitelist (arithmetic, comparisons, ``and``/``or``/``not``, a few functions
and constants, and the variables the caller allows), and the tree is turned
into a closure that evaluates with numpy.  Anything else (attribute access,
subscripts, other calls, lambdas, comprehensions, dunder names, strings) is
rejected with an :class:`ExpressionError` naming the offending part.

Examples
--------
>>> import numpy as np
>>> f = compile_expression("0.01*cos(pi*x/5)", ("x", "y"))
>>> float(f(x=np.array([0.0]), y=np.array([0.0]))[0])
0.01
>>> compile_expression("x <= 0 and y > 1", ("x", "y"))(x=np.array([0.0, 1.0]), y=np.array([2.0, 2.0])).tolist()
[True, False]
>>> compile_expression("__import__('os')", ("x",))
Traceback (most recent call last):
...
femgrid_mpm.expressions.ExpressionError: name '__import__' is not allowed in expression "__import__('os')" (allowed: x, pi, e, sin, cos, tan, exp, log, sqrt, abs, min, max)
"""

from __future__ import annotations

import ast
import operator
import unicodedata
from functools import reduce
from typing import Callable

import numpy as np

MAX_LENGTH = 1000
#: deepest nesting of the expression's syntax tree, operators and leaves counted (a sum of
#: n terms is n + 1 deep): the checks and the evaluation recurse once per level, and Python's
#: stack would end near 500
MAX_DEPTH = 100

FUNCTIONS: dict[str, Callable] = {
    "sin": np.sin,
    "cos": np.cos,
    "tan": np.tan,
    "exp": np.exp,
    "log": np.log,
    "sqrt": np.sqrt,
    "abs": np.abs,
    "min": lambda *args: reduce(np.minimum, args),
    "max": lambda *args: reduce(np.maximum, args),
}
#: numpy scalars, like every literal (below): arithmetic on them follows IEEE (1/0 is inf, which
#: the callers' finiteness checks name) instead of raising Python's ZeroDivisionError
CONSTANTS = {"pi": np.float64(np.pi), "e": np.float64(np.e)}

_BINARY = {
    ast.Add: operator.add,
    ast.Sub: operator.sub,
    ast.Mult: operator.mul,
    ast.Div: operator.truediv,
    ast.Pow: operator.pow,
    ast.Mod: operator.mod,
    ast.FloorDiv: operator.floordiv,
}
_UNARY = {ast.USub: operator.neg, ast.UAdd: operator.pos, ast.Not: np.logical_not}
_COMPARE = {
    ast.Lt: operator.lt,
    ast.LtE: operator.le,
    ast.Gt: operator.gt,
    ast.GtE: operator.ge,
    ast.Eq: operator.eq,
    ast.NotEq: operator.ne,
}


class ExpressionError(ValueError):
    """An expression that is malformed or uses something not whitelisted."""


Evaluator = Callable[[dict], np.ndarray]


def compile_expression(text: str, variables: tuple[str, ...],
                       constants: dict[str, float] | None = None) -> Callable[..., np.ndarray]:
    """Compile ``text`` into ``f(**values) -> ndarray`` after checking it.

    Parameters
    ----------
    text : str
        The expression.
    variables : tuple of str
        Names the expression may use as variables (e.g. ``("x", "y")``).
    constants : dict of str to float, optional
        Named numbers the expression may use besides ``pi`` and ``e`` (a scene
        table's ``constants = { w = 1.987 }``); see :func:`check_constants`.

    Returns
    -------
    callable
        ``f(x=..., y=...)``: evaluates elementwise and broadcasts the result
        to the shape of the first variable given.
    """
    if not isinstance(text, str):
        raise ExpressionError(f"expression must be a string, got {type(text).__name__}")
    if len(text) > MAX_LENGTH:
        raise ExpressionError(f"expression is longer than {MAX_LENGTH} characters")
    try:
        tree = ast.parse(text.strip(), mode="eval")
    except SyntaxError as error:
        raise ExpressionError(f"cannot parse expression {text!r}: {error.msg}") from None
    if _depth(tree.body) > MAX_DEPTH:
        raise ExpressionError(f"expression nests more than {MAX_DEPTH} deep: {_shortened(text)!r}")
    named = {**CONSTANTS, **{name: np.float64(value) for name, value in check_constants(constants or {}, variables).items()}}
    allowed = ", ".join((*variables, *named, *FUNCTIONS))
    evaluate = _Compiler(text, set(variables), allowed, named).visit(tree.body)

    def expression(**values: np.ndarray) -> np.ndarray:
        missing = set(variables) - set(values)
        if missing:
            raise ExpressionError(f"expression {text!r} needs values for {sorted(missing)}")
        shape = np.shape(next(iter(values.values()))) if values else ()
        with np.errstate(all="ignore"):  # every operand is a numpy float: 1/0 is inf, not an exception
            result = evaluate(values)
        return np.broadcast_to(np.asarray(result), shape)

    expression.text = text  # type: ignore[attr-defined]
    return expression


def check_constants(constants: dict, variables: tuple[str, ...]) -> dict[str, float]:
    """``constants`` checked: names that are identifiers and shadow neither a variable,
    ``pi``/``e`` nor a function; values that are finite numbers.

    >>> check_constants({"w": 2}, ("x", "t"))
    {'w': 2.0}
    >>> check_constants({"t": 1.0}, ("x", "t"))
    Traceback (most recent call last):
    ...
    femgrid_mpm.expressions.ExpressionError: constant 't' would hide the variable 't'
    """
    checked = {}
    for name, value in constants.items():
        if not isinstance(name, str) or not name.isidentifier() or name.startswith("_"):
            raise ExpressionError(f"constant name {name!r} is not a plain name (letters, digits, _; not starting with _)")
        written, name = name, unicodedata.normalize("NFKC", name)  # as Python reads the expression's names
        if name in variables:
            raise ExpressionError(f"constant {written!r} would hide the variable {name!r}")
        if name in CONSTANTS or name in FUNCTIONS:
            raise ExpressionError(f"constant {written!r} would hide the built-in {name!r}")
        if name in checked:
            raise ExpressionError(f"constant {written!r} is the constant {name!r} again (the same name to Python)")
        try:
            number = float(value) if isinstance(value, (int, float)) and not isinstance(value, bool) else None
        except OverflowError:
            number = None
        if number is None or not np.isfinite(number):
            raise ExpressionError(f"constant {name!r} must be a finite number, got {_shortened(repr(value))}")
        checked[name] = number
    return checked


def compile_vector(key: str, components, variables: tuple[str, ...], constants: dict) -> list:
    """A scene's two-component field (numbers or expressions, e.g. a body force's
    ``acceleration``) with its table's ``constants``: each component a number or a
    compiled expression.  Raises ValueError naming ``constants`` or ``key[i]``."""
    try:
        check_constants(constants, variables)
    except ValueError as error:
        raise ValueError(f"constants: {error}") from None
    compiled = []
    for index, component in enumerate(components):
        try:
            compiled.append(compile_expression(component, variables, constants) if isinstance(component, str)
                            else float(component))
        except ValueError as error:
            raise ValueError(f"{key}[{index}]: {error}") from None
    return compiled


def evaluate_vector(components: list, n: int, **values) -> np.ndarray:
    """(n, 2): the components of :func:`compile_vector` evaluated at ``values``."""
    field = np.empty((n, 2))
    for axis, component in enumerate(components):
        field[:, axis] = component(**values) if callable(component) else component
    return field


class _Compiler:
    """Turns a checked AST into nested closures; rejects everything else."""

    def __init__(self, text: str, variables: set[str], allowed: str, constants: dict[str, np.float64]):
        self.text = text
        self.variables = variables
        self.allowed = allowed
        self.constants = constants

    def fail(self, what: str) -> ExpressionError:
        return ExpressionError(f"{what} is not allowed in expression {self.text!r}")

    def visit(self, node: ast.AST) -> Evaluator:
        method = getattr(self, f"visit_{type(node).__name__}", None)
        if method is None:
            raise self.fail(_describe(node))
        return method(node)

    def visit_Constant(self, node: ast.Constant) -> Evaluator:
        if isinstance(node.value, bool) or not isinstance(node.value, (int, float)):
            raise self.fail(f"the constant {node.value!r}")
        try:
            value = np.float64(node.value)
        except OverflowError:
            raise ExpressionError(f"the constant {_shortened(str(node.value))} is too large for a float "
                                  f"in expression {_shortened(self.text)!r}") from None
        return lambda values: value

    def visit_Name(self, node: ast.Name) -> Evaluator:
        name = node.id
        if name in self.variables:
            return lambda values: values[name]
        if name in self.constants:
            value = self.constants[name]
            return lambda values: value
        raise ExpressionError(
            f"name {name!r} is not allowed in expression {self.text!r} (allowed: {self.allowed})"
        )

    def number(self, node: ast.AST) -> Evaluator:
        """An operand of ``-`` (either), unary ``-`` or ``+``: a comparison or a logical operation
        counts as 1.0 or 0.0 (numpy refuses them on booleans: ``(x < 1) - (x > 2)`` and
        ``-(x < 1)`` failed when evaluated, after the scene had been taken).  Elsewhere booleans
        stay numpy's (``(x <= 0) + (x >= 10)`` is a node condition, their logical or)."""
        evaluate = self.visit(node)
        if isinstance(node, (ast.Compare, ast.BoolOp)) or (isinstance(node, ast.UnaryOp) and isinstance(node.op, ast.Not)):
            return lambda values: np.asarray(evaluate(values), dtype=float)
        return evaluate

    def visit_BinOp(self, node: ast.BinOp) -> Evaluator:
        op = _BINARY.get(type(node.op))
        if op is None:
            raise self.fail(f"the operator {type(node.op).__name__}")
        operand = self.number if isinstance(node.op, ast.Sub) else self.visit
        left, right = operand(node.left), operand(node.right)
        return lambda values: op(left(values), right(values))

    def visit_UnaryOp(self, node: ast.UnaryOp) -> Evaluator:
        op = _UNARY.get(type(node.op))
        if op is None:
            raise self.fail(f"the operator {type(node.op).__name__}")
        operand = self.visit(node.operand) if isinstance(node.op, ast.Not) else self.number(node.operand)
        return lambda values: op(operand(values))

    def visit_BoolOp(self, node: ast.BoolOp) -> Evaluator:
        combine = np.logical_and if isinstance(node.op, ast.And) else np.logical_or
        parts = [self.visit(value) for value in node.values]
        return lambda values: reduce(combine, (part(values) for part in parts))

    def visit_Compare(self, node: ast.Compare) -> Evaluator:
        operands = [self.visit(node.left), *(self.visit(c) for c in node.comparators)]
        ops = []
        for op in node.ops:
            if type(op) not in _COMPARE:
                raise self.fail(f"the comparison {type(op).__name__}")
            ops.append(_COMPARE[type(op)])

        def compare(values: dict) -> np.ndarray:
            evaluated = [operand(values) for operand in operands]
            pairs = (op(a, b) for op, a, b in zip(ops, evaluated, evaluated[1:]))
            return reduce(np.logical_and, pairs)

        return compare

    def visit_Call(self, node: ast.Call) -> Evaluator:
        if not isinstance(node.func, ast.Name):
            # e.g. __import__('os').getcwd(): name what is called, not "name 'attribute access'"
            raise self.fail("calling the result of a call" if isinstance(node.func, ast.Call) else _describe(node.func))
        if node.func.id not in FUNCTIONS:
            name = node.func.id
            raise ExpressionError(
                f"name {name!r} is not allowed in expression {self.text!r} (allowed: {self.allowed})"
            )
        if node.keywords or any(isinstance(arg, ast.Starred) for arg in node.args):
            raise self.fail("keyword or starred arguments")
        name = node.func.id
        expected = (2, 64) if name in ("min", "max") else (1, 1)
        if not expected[0] <= len(node.args) <= expected[1]:
            takes = f"{expected[0]} argument" if expected == (1, 1) else f"{expected[0]} to {expected[1]} arguments"
            raise ExpressionError(f"{name}() takes {takes}, got {len(node.args)} in {self.text!r}")
        function = FUNCTIONS[name]
        args = [self.visit(arg) for arg in node.args]
        return lambda values: function(*(arg(values) for arg in args))


def _depth(node: ast.AST) -> int:
    """Nesting depth of an expression tree (iterative: a deep tree must not overflow the stack)."""
    deepest, stack = 0, [(node, 1)]
    while stack:
        current, depth = stack.pop()
        deepest = max(deepest, depth)
        stack.extend((child, depth + 1) for child in ast.iter_child_nodes(current))
    return deepest


def _shortened(text: str, limit: int = 60) -> str:
    """``text``, cut to ``limit`` characters for a one-line message."""
    return text if len(text) <= limit else text[: limit - 3] + "..."


def _describe(node: ast.AST) -> str:
    kinds = {
        "Attribute": "attribute access",
        "Subscript": "indexing",
        "Lambda": "lambda",
        "ListComp": "a comprehension",
        "GeneratorExp": "a comprehension",
        "List": "a list",
        "Tuple": "a tuple",
        "Dict": "a dict",
        "IfExp": "a conditional expression",
        "NamedExpr": "assignment",
        "JoinedStr": "a string",
    }
    return kinds.get(type(node).__name__, f"the syntax {type(node).__name__}")
