"""A small, safe expression language for procedural channels and force fields.

Text is parsed with Python's `ast` (mode "eval") and then translated, node by node, into
our own restricted tree; anything outside the grammar is rejected with an
`ExpressionError` naming the construct and its column. The tree is evaluated with numpy,
vectorised over whatever arrays the caller binds to the variables. Nothing is ever passed
to `eval`/`exec`, and no Python object other than numbers and arrays is reachable.

Grammar (docs/expressions.md):

    expr   := expr ('+' | '-' | '*' | '/' | '%' | '**' | '^') expr | ('+' | '-') expr
            | NUMBER | NAME | FUNC '(' expr (',' expr)* ')' | '(' expr ')'

>>> import numpy as np
>>> e = parse_expression("2 * sin(pi * t / 2) + max(t, 1)", ("t",))
>>> e.evaluate({"t": np.array([0.0, 1.0])}).tolist()
[1.0, 3.0]
>>> parse_expression("__import__('os')", ("t",))
Traceback (most recent call last):
...
motion.pipeline.expr.ExpressionError: expression "__import__('os')": '__import__' is not an allowed function (allowed: abs, clamp, cos, exp, floor, log, max, min, pow, sin, sqrt, tan) (column 1)
"""

from __future__ import annotations

import ast
import math
from dataclasses import dataclass
from functools import cache
from typing import TYPE_CHECKING, Callable, Mapping, Sequence

if TYPE_CHECKING:  # numpy is imported when an expression is evaluated, not when one is parsed
    import numpy as np

from .errors import MotionError

MAX_LENGTH = 1000  # characters of source text
MAX_DEPTH = 100  # nesting depth of the tree (a + b + c ... nests to the left)
MAX_PARENS = 32  # nesting depth of parentheses
MAX_NODES = 400  # nodes in the tree
MAX_EXPONENT = 64.0  # |constant exponent| of ** / pow
MAX_LITERAL = 1e12  # |numeric literal|

CONSTANTS: dict[str, float] = {"pi": math.pi, "e": math.e}

ArrayFn = Callable[..., "np.ndarray"]

# name -> (min arity, max arity); the numpy function of each name is in `_numpy_tables`.
FUNCTIONS: dict[str, tuple[int, int]] = {
    "sin": (1, 1),
    "cos": (1, 1),
    "tan": (1, 1),
    "exp": (1, 1),
    "log": (1, 1),
    "sqrt": (1, 1),
    "abs": (1, 1),
    "floor": (1, 1),
    "min": (2, 16),
    "max": (2, 16),
    "clamp": (3, 3),
    "pow": (2, 2),
}

_BINARY: dict[type, str] = {ast.Add: "+", ast.Sub: "-", ast.Mult: "*", ast.Div: "/", ast.Mod: "%", ast.Pow: "**"}


@cache
def _numpy_tables() -> tuple[dict[str, ArrayFn], dict[str, ArrayFn]]:
    """The numpy function of each name in FUNCTIONS and of each binary operator, built on the
    first evaluation (a process that only parses, such as `motion validate`, never imports numpy)."""
    import numpy as np

    def clamp(x: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
        return np.minimum(np.maximum(x, lo), hi)

    def fold(op: ArrayFn) -> ArrayFn:
        def folded(*args: np.ndarray) -> np.ndarray:
            out = args[0]
            for a in args[1:]:
                out = op(out, a)
            return out

        return folded

    functions: dict[str, ArrayFn] = {
        "sin": np.sin, "cos": np.cos, "tan": np.tan, "exp": np.exp, "log": np.log, "sqrt": np.sqrt, "abs": np.abs,
        "floor": np.floor, "min": fold(np.minimum), "max": fold(np.maximum), "clamp": clamp, "pow": np.power,
    }
    ops: dict[str, ArrayFn] = {"+": np.add, "-": np.subtract, "*": np.multiply, "/": np.true_divide, "%": np.mod, "**": np.power}
    return functions, ops


# What users most often try, with the name we report.
_FORBIDDEN: dict[type, str] = {
    ast.Attribute: "attribute access",
    ast.Subscript: "a subscript",
    ast.Lambda: "a lambda",
    ast.ListComp: "a comprehension",
    ast.SetComp: "a comprehension",
    ast.DictComp: "a comprehension",
    ast.GeneratorExp: "a comprehension",
    ast.NamedExpr: "an assignment expression",
    ast.Starred: "a starred argument",
    ast.JoinedStr: "a string",
    ast.List: "a list",
    ast.Tuple: "a tuple",
    ast.Dict: "a dict",
    ast.Set: "a set",
    ast.Compare: "a comparison",
    ast.BoolOp: "a boolean operator",
    ast.IfExp: "a conditional expression",
    ast.Await: "await",
    ast.Yield: "yield",
    ast.YieldFrom: "yield",
    ast.Slice: "a slice",
}


class ExpressionError(MotionError, ValueError):
    """An expression is malformed, unsafe or over a limit; the message says which and where."""


# --- the restricted tree ------------------------------------------------------------------


@dataclass(frozen=True)
class Num:
    """A number literal (constants such as pi are folded into one)."""

    value: float


@dataclass(frozen=True)
class Var:
    """A variable bound at evaluation (t; x, y, z for force fields)."""

    name: str


@dataclass(frozen=True)
class Neg:
    """Unary minus."""

    operand: "Node"


@dataclass(frozen=True)
class BinOp:
    """A binary operator: + - * / % ** (^ is **)."""

    op: str
    left: "Node"
    right: "Node"


@dataclass(frozen=True)
class Call:
    """A call of an allowed function (sin, clamp, ...) with its checked number of arguments."""

    func: str
    args: tuple["Node", ...]


Node = Num | Var | Neg | BinOp | Call


@dataclass(frozen=True)
class Expression:
    """A parsed expression: `text`, its `variables` (names the caller binds) and `tree`."""

    text: str
    variables: tuple[str, ...]
    tree: Node

    @property
    def is_constant(self) -> bool:
        """True when no variable occurs in the tree (the value does not depend on inputs)."""
        return not _uses_variables(self.tree)

    def evaluate(self, values: Mapping[str, np.ndarray | float], shape: tuple[int, ...] | None = None) -> np.ndarray:
        """Evaluate over arrays: variables broadcast with numpy rules; the result has the
        broadcast shape of the bound variables (or `shape`), dtype float64.

        Domain errors (log of a negative, 0/0) give nan/inf, never an exception; callers
        that need finite values check with `np.isfinite`."""
        missing = [v for v in self.variables if v not in values]
        if missing:
            raise ExpressionError(f"expression {self.text!r}: no value bound for {', '.join(missing)}")
        import numpy as np

        env = {name: np.asarray(values[name], dtype=np.float64) for name in self.variables}
        if shape is None:
            shape = np.broadcast_shapes(*(a.shape for a in env.values())) if env else ()
        with np.errstate(all="ignore"):
            out = _eval(self.tree, env)
        return np.array(np.broadcast_to(out, shape), dtype=np.float64)

    def __call__(self, **values: np.ndarray | float) -> np.ndarray:
        """`expr(t=times)` is `expr.evaluate({"t": times})`."""
        return self.evaluate(values)


def _uses_variables(node: Node) -> bool:
    if isinstance(node, Var):
        return True
    if isinstance(node, Neg):
        return _uses_variables(node.operand)
    if isinstance(node, BinOp):
        return _uses_variables(node.left) or _uses_variables(node.right)
    if isinstance(node, Call):
        return any(_uses_variables(a) for a in node.args)
    return False


def _eval(node: Node, env: Mapping[str, np.ndarray]) -> np.ndarray:
    import numpy as np

    functions, ops = _numpy_tables()
    if isinstance(node, Num):
        return np.float64(node.value)  # type: ignore[return-value]
    if isinstance(node, Var):
        return env[node.name]
    if isinstance(node, Neg):
        return np.negative(_eval(node.operand, env))
    if isinstance(node, BinOp):
        return ops[node.op](_eval(node.left, env), _eval(node.right, env))
    fn = functions[node.func]
    return fn(*(_eval(a, env) for a in node.args))


# --- parsing ------------------------------------------------------------------------------


def parse_expression(text: str, variables: Sequence[str]) -> Expression:
    """Parse `text` into a restricted tree over `variables` (e.g. ("t",) or ("t", "x", "y", "z")).

    Raises ExpressionError for anything outside the grammar: unknown names, calls of
    non-whitelisted functions, attribute access, subscripts, lambdas, comprehensions,
    strings, constant exponents above MAX_EXPONENT, nesting deeper than MAX_DEPTH (tree) or
    MAX_PARENS (parentheses), more
    than MAX_NODES nodes or text longer than MAX_LENGTH characters.
    """
    variables = tuple(variables)
    for v in variables:
        if v in FUNCTIONS or v in CONSTANTS or not v.isidentifier():
            raise ExpressionError(f"variable name {v!r} is not usable in expressions")
    shown = text if len(text) <= 60 else text[:57] + "..."
    fail = _failer(shown)
    module = _python_tree(text, shown, fail)
    # Python's parser accepts `1 if t else 2` etc.; everything goes through `build`.
    return Expression(text=text, variables=variables, tree=_TreeBuilder(variables, fail).build(module.body, 1))


def _failer(shown: str) -> Callable[..., ExpressionError]:
    """The error for the expression `shown`: the message, and the node's column if given."""

    def fail(message: str, node: ast.AST | None = None) -> ExpressionError:
        col = getattr(node, "col_offset", None)
        where = f" (column {col + 1})" if col is not None else ""
        return ExpressionError(f"expression {shown!r}: {message}{where}")

    return fail


def _python_tree(text: str, shown: str, fail: Callable[..., ExpressionError]) -> ast.Expression:
    """Python's syntax tree of `text`, after the cheap checks (type, length, emptiness,
    parenthesis depth) that keep the parser from pathological input."""
    if not isinstance(text, str):
        raise ExpressionError(f"an expression must be text, got {type(text).__name__}")
    if len(text) > MAX_LENGTH:
        raise fail(f"too long ({len(text)} characters; the limit is {MAX_LENGTH})")
    if not text.strip():
        raise fail("empty expression")
    # Cheap pre-check so the parser never sees pathological nesting.
    depth = peak = 0
    for ch in text:
        depth += ch == "("
        depth -= ch == ")"
        peak = max(peak, depth)
    if peak > MAX_PARENS:
        raise fail(f"nested too deeply ({peak} levels of parentheses; the limit is {MAX_PARENS})")
    try:
        # `^` means power (as in every animation package), with the precedence of `**`;
        # Python would read it as xor with the lowest precedence, so rewrite it first.
        return ast.parse(text.strip().replace("^", "**"), mode="eval")
    except SyntaxError as exc:
        col = f" (column {exc.offset})" if exc.offset else ""
        raise ExpressionError(f"expression {shown!r}: syntax error: {exc.msg}{col}") from None
    except (RecursionError, MemoryError, ValueError):
        raise fail("cannot be parsed (too complex)") from None


class _TreeBuilder:
    """Python's syntax tree -> our restricted tree over `variables`, node by node, counting
    nodes and depth; anything outside the grammar raises through `fail`."""

    def __init__(self, variables: tuple[str, ...], fail: Callable[..., ExpressionError]) -> None:
        self.variables = variables
        self.fail = fail
        self.count = 0

    def build(self, node: ast.AST, level: int) -> Node:
        """The restricted tree of `node`, at nesting `level`."""
        fail = self.fail
        self.count += 1
        if self.count > MAX_NODES:
            raise fail(f"too many terms (the limit is {MAX_NODES})")
        if level > MAX_DEPTH:
            raise fail(f"nested too deeply (the limit is {MAX_DEPTH} levels)", node)
        if isinstance(node, ast.Constant):
            return self.constant(node)
        if isinstance(node, ast.Name):
            return self.name(node)
        if isinstance(node, ast.UnaryOp):
            return self.unary(node, level)
        if isinstance(node, ast.BinOp):
            return self.binary(node, level)
        if isinstance(node, ast.Call):
            return self.call(node, level)
        what = _FORBIDDEN.get(type(node), type(node).__name__)
        raise fail(f"{what} is not allowed here", node)

    def constant(self, node: ast.Constant) -> Node:
        """A finite number no larger than MAX_LITERAL."""
        if isinstance(node.value, bool) or not isinstance(node.value, (int, float)):
            raise self.fail(f"only numbers are allowed as literals, got {type(node.value).__name__} {node.value!r}", node)
        value = float(node.value)
        if not math.isfinite(value) or abs(value) > MAX_LITERAL:
            raise self.fail(f"number {node.value!r} is too large (limit {MAX_LITERAL:g})", node)
        return Num(value)

    def name(self, node: ast.Name) -> Node:
        """A variable or a named constant."""
        if node.id in self.variables:
            return Var(node.id)
        if node.id in CONSTANTS:
            return Num(CONSTANTS[node.id])
        if node.id in FUNCTIONS:
            raise self.fail(f"function '{node.id}' must be called, e.g. {node.id}(t)", node)
        known = ", ".join([*self.variables, *CONSTANTS])
        raise self.fail(f"unknown name '{node.id}' (known: {known})", node)

    def unary(self, node: ast.UnaryOp, level: int) -> Node:
        """-x (folded into a negative number when x is one) or +x."""
        if isinstance(node.op, ast.USub):
            inner = self.build(node.operand, level + 1)
            return Num(-inner.value) if isinstance(inner, Num) else Neg(inner)
        if isinstance(node.op, ast.UAdd):
            return self.build(node.operand, level + 1)
        raise self.fail(f"operator '{type(node.op).__name__}' is not allowed", node)

    def binary(self, node: ast.BinOp, level: int) -> Node:
        """+ - * / % **, a constant exponent bounded."""
        op = _BINARY.get(type(node.op))
        if op is None:
            raise self.fail(f"operator '{type(node.op).__name__}' is not allowed (use + - * / % **)", node)
        left = self.build(node.left, level + 1)
        right = self.build(node.right, level + 1)
        if op == "**":
            _check_exponent(right, node, self.fail)
        return BinOp(op, left, right)

    def call(self, node: ast.Call, level: int) -> Node:
        """A whitelisted function by name, with its number of positional arguments."""
        fail = self.fail
        if not isinstance(node.func, ast.Name):
            what = _FORBIDDEN.get(type(node.func), type(node.func).__name__)
            raise fail(f"only whitelisted functions may be called ({what} is not allowed)", node)
        name = node.func.id
        if name not in FUNCTIONS:
            raise fail(f"'{name}' is not an allowed function (allowed: {', '.join(sorted(FUNCTIONS))})", node)
        if node.keywords:
            raise fail(f"'{name}' takes no keyword arguments", node)
        lo, hi = FUNCTIONS[name]
        n = len(node.args)
        if not lo <= n <= hi:
            want = str(lo) if lo == hi else f"{lo} to {hi}"
            raise fail(f"'{name}' takes {want} arguments, got {n}", node)
        args = tuple(self.build(a, level + 1) for a in node.args)
        if name == "pow":
            _check_exponent(args[1], node, fail)
        return Call(name, args)


def _check_exponent(exponent: Node, node: ast.AST, fail: Callable[..., ExpressionError]) -> None:
    """Reject constant exponents whose magnitude exceeds MAX_EXPONENT (`9**9**9`)."""
    if not _uses_variables(exponent):
        import numpy as np

        with np.errstate(all="ignore"):
            value = float(_eval(exponent, {}))
        if not math.isfinite(value) or abs(value) > MAX_EXPONENT:
            raise fail(f"exponent too large ({value:g}; the limit is {MAX_EXPONENT:g})", node)
