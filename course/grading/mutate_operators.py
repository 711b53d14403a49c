"""The operator mutations of generated mutants: each site of a function's source where one
small change applies (:func:`generate`, one :class:`Generated` per change, identified by
``module:function:kind:n``). Part of :mod:`course.grading.mutate`, whose docstring lists
the operators; that module plans and grades them.
"""

from __future__ import annotations

import ast
import math
from dataclasses import dataclass


@dataclass(frozen=True)
class Generated:
    """One mutation: replace ``source[start:end]`` of ``file`` by ``replacement``."""

    id: str  # module:function:kind:n
    module: str
    function: str
    kind: str
    line: int
    start: int
    end: int
    original: str
    replacement: str
    file: str  # the file defining ``function`` (the module, or a file of its package), as
    # copy_module names it: lab1_intersect.py, lab2_accel/grid.py

    @property
    def lab(self) -> int:
        return int(self.module.split("_")[0].removeprefix("lab"))

    def apply(self, source: str) -> str:
        assert source[self.start : self.end] == self.original, self.id
        return source[: self.start] + self.replacement + source[self.end :]


_CMP_SWAP = {
    ast.Lt: ast.LtE,
    ast.LtE: ast.Lt,
    ast.Gt: ast.GtE,
    ast.GtE: ast.Gt,
    ast.Eq: ast.NotEq,
    ast.NotEq: ast.Eq,
}
_CMP_FLIP = {ast.Lt: ast.Gt, ast.LtE: ast.GtE, ast.Gt: ast.Lt, ast.GtE: ast.LtE}
_BIN_SWAP = {
    ast.Add: ast.Sub,
    ast.Sub: ast.Add,
    ast.Mult: ast.Div,
    ast.Div: ast.Mult,
    ast.BitAnd: ast.BitOr,
    ast.BitOr: ast.BitAnd,
}
_ROUNDING = {"floor": "ceil", "ceil": "floor", "round": "floor", "trunc": "floor"}
_DROPPED = {"abs", "clamp", "clamp_min", "clamp_max", "clip", "nan_to_num"}
_SWAPPED = {"where": (1, 2), "cross": (0, 1), "atan2": (0, 1)}


def _call_name(node: ast.Call) -> str | None:
    func = node.func
    return (
        func.attr
        if isinstance(func, ast.Attribute)
        else (func.id if isinstance(func, ast.Name) else None)
    )


def _is_docstring(node, parents) -> bool:
    parent = parents.get(node)
    return (
        isinstance(parent, ast.Expr)
        and isinstance(node, ast.Constant)
        and isinstance(node.value, str)
    )


def _in_raise(node, parents) -> bool:
    """Error branches are the input contract's business, tested apart; their messages and
    conditions would only add noise."""
    while node in parents:
        node = parents[node]
        if isinstance(node, ast.Raise):
            return True
    return False


def _is_axis_keyword(node, parents) -> bool:
    """``dim=-1``-like arguments: a wrong axis fails at once on shape, it teaches nothing."""
    parent = parents.get(node)
    if isinstance(parent, ast.UnaryOp):
        parent = parents.get(parent)
    return isinstance(parent, ast.keyword) and parent.arg in ("dim", "axis", "device", "dtype")


def _mutations(node: ast.AST) -> list[tuple[str, ast.AST]]:
    """(kind, replacement node) for one AST node; the replacement is unparsed in place."""
    out = []
    if isinstance(node, ast.Compare) and len(node.ops) == 1:
        op = type(node.ops[0])
        if op in _CMP_SWAP:
            out.append(
                (
                    f"cmp_{op.__name__}_{_CMP_SWAP[op].__name__}",
                    ast.Compare(node.left, [_CMP_SWAP[op]()], node.comparators),
                )
            )
        if op in _CMP_FLIP:
            out.append(
                (
                    f"cmp_{op.__name__}_{_CMP_FLIP[op].__name__}",
                    ast.Compare(node.left, [_CMP_FLIP[op]()], node.comparators),
                )
            )
    elif isinstance(node, ast.BinOp) and type(node.op) in _BIN_SWAP:
        new = _BIN_SWAP[type(node.op)]
        out.append(
            (f"op_{type(node.op).__name__}_{new.__name__}", ast.BinOp(node.left, new(), node.right))
        )
    elif isinstance(node, ast.BoolOp):
        new = ast.Or if isinstance(node.op, ast.And) else ast.And
        out.append(
            (f"bool_{type(node.op).__name__}_{new.__name__}", ast.BoolOp(new(), node.values))
        )
    elif (
        isinstance(node, ast.UnaryOp)
        and isinstance(node.op, ast.USub)
        and not isinstance(node.operand, ast.Constant)
    ):
        out.append(("drop_neg", node.operand))
    elif isinstance(node, ast.Constant) and type(node.value) in (int, float):
        value = node.value
        if isinstance(value, int):
            out.append(("const_int", ast.Constant(value + 1)))
        elif value == 0.0:
            out.append(("const_float", ast.Constant(1e-3)))
        elif math.isfinite(value):
            out.append(("const_float", ast.Constant(value * 1.1)))
    elif isinstance(node, ast.Attribute) and node.attr == "float64":
        out.append(("narrow_dtype", ast.Attribute(node.value, "float32")))
    elif isinstance(node, ast.Call):
        name = _call_name(node)
        method = isinstance(node.func, ast.Attribute)
        if name == "double" and method and not node.args:
            out.append(("narrow_double", ast.Call(ast.Attribute(node.func.value, "float"), [], [])))
        if name in _ROUNDING and method:
            out.append(
                (
                    f"round_{name}_{_ROUNDING[name]}",
                    ast.Call(
                        ast.Attribute(node.func.value, _ROUNDING[name]), node.args, node.keywords
                    ),
                )
            )
        if name in _DROPPED:
            # torch.abs(x) / x.abs(): keep x
            is_torch = (
                method
                and isinstance(node.func.value, ast.Name)
                and node.func.value.id in ("torch", "np", "math")
            )
            if is_torch and node.args:
                out.append((f"drop_{name}", node.args[0]))
            elif method and not is_torch:
                out.append((f"drop_{name}", node.func.value))
            elif not method and name == "abs" and node.args:
                out.append(("drop_abs", node.args[0]))
        if name in _SWAPPED:
            i, j = _SWAPPED[name]
            if len(node.args) > j:
                args = list(node.args)
                args[i], args[j] = args[j], args[i]
                out.append((f"swap_{name}", ast.Call(node.func, args, node.keywords)))
    return out


def _offsets(source: str) -> list[int]:
    starts, total = [], 0
    for line in source.splitlines(keepends=True):
        starts.append(total)
        total += len(line)
    starts.append(total)
    return starts


def _position(lines, starts, lineno, col_bytes) -> int:
    """Character offset in the module of (line, UTF-8 byte column), as ``ast`` reports it."""
    return starts[lineno - 1] + len(lines[lineno - 1].encode()[:col_bytes].decode())


def _functions(tree, names):
    """(qualified name, node) of each top-level def/class named in ``names``."""
    for node in tree.body:
        if isinstance(node, (ast.FunctionDef, ast.ClassDef)) and node.name in names:
            yield node.name, node


def generate(module: str, source: str, functions, file: str | None = None) -> list[Generated]:
    """Every mutation of the named top-level functions/classes of one module's file ``file``
    (``module.py`` by default; or one of its package's files) whose text is ``source``."""
    tree = ast.parse(source)
    parents = {child: parent for parent in ast.walk(tree) for child in ast.iter_child_nodes(parent)}
    starts = _offsets(source)
    lines = source.splitlines(keepends=True)
    found = []
    for qualname, top in _functions(tree, set(functions)):
        counters: dict[str, int] = {}
        body_nodes = [n for n in ast.walk(top) if hasattr(n, "lineno") and n is not top]
        body_nodes.sort(key=lambda n: (n.lineno, n.col_offset))
        for node in body_nodes:
            if _is_docstring(node, parents) or _in_raise(node, parents):
                continue
            if isinstance(node, ast.Constant) and _is_axis_keyword(node, parents):
                continue
            for kind, new in _mutations(node):
                n = counters.get(kind, 0)
                counters[kind] = n + 1
                start = _position(lines, starts, node.lineno, node.col_offset)
                end = _position(lines, starts, node.end_lineno, node.end_col_offset)
                original = source[start:end]
                replacement = ast.unparse(new)
                if isinstance(node, (ast.BinOp, ast.BoolOp, ast.Compare)) or kind == "drop_neg":
                    replacement = f"({replacement})"
                if replacement.strip("()") == original.strip("()"):
                    continue
                found.append(
                    Generated(
                        id=f"{module}:{qualname}:{kind}:{n}",
                        module=module,
                        function=qualname,
                        kind=kind,
                        line=node.lineno,
                        start=start,
                        end=end,
                        original=original,
                        replacement=replacement,
                        file=file or f"{module}.py",
                    )
                )
    return found
