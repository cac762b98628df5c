"""No module keeps state on another object behind its back (issue 32, "without reach-ins").

State lives where it is declared: a component's own attributes, or a declared cache object
(:class:`dynsens.models.multibody.run_cache.RunCache`, the parameter sets' ``cache`` fields).
This test walks every module of ``dynsens/`` with :mod:`ast` and fails on

* writes through another object's ``__dict__`` or ``vars(...)``: ``x.__dict__[k] = v``,
  ``x.__dict__.setdefault(...)`` / ``.update(...)`` / ``.pop(...)``, the same on ``vars(x)``
  (``self`` is the object's own; so is an object the function itself made with
  ``object.__new__``, whose attributes it fills);
* ``setattr(x, ...)`` and ``object.__setattr__(x, ...)`` on anything but ``self``;
* dunder-shaped string keys, ``d["__x__"]`` or ``d.get("__x__")``: extras smuggled into a
  table of other entries (``sys.modules["__main__"]`` is the interpreter's own name).
"""
from __future__ import annotations

import ast
import re
from pathlib import Path

import pytest

import dynsens

PACKAGE = Path(dynsens.__file__).parent
DUNDER = re.compile(r"^__\w+__$")
DICT_WRITES = {"setdefault", "update", "pop", "popitem", "clear", "__setitem__", "__delitem__"}
KEY_CALLS = {"get", "setdefault", "pop", "__getitem__", "__setitem__", "__delitem__"}


def _name(node: ast.AST) -> str:
    return ast.unparse(node)


def _namespace_of(node: ast.AST) -> ast.AST | None:
    """X when node is ``X.__dict__`` or ``vars(X)``; else None."""
    if isinstance(node, ast.Attribute) and node.attr == "__dict__":
        return node.value
    if isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.func.id == "vars" \
            and len(node.args) == 1:
        return node.args[0]
    return None


def _made_here(func: ast.AST) -> set[str]:
    """Names a function binds to ``object.__new__(...)``: objects it makes itself."""
    out = set()
    for node in ast.walk(func):
        if isinstance(node, (ast.Assign, ast.AnnAssign)) and isinstance(node.value, ast.Call) \
                and _name(node.value.func) == "object.__new__":
            for tgt in node.targets if isinstance(node, ast.Assign) else [node.target]:
                if isinstance(tgt, ast.Name):
                    out.add(tgt.id)
    return out


class _Finder(ast.NodeVisitor):
    def __init__(self, where: str):
        self.where = where
        self.found: list[str] = []
        self.own: list[set[str]] = [set()]

    def _add(self, node: ast.AST, what: str) -> None:
        self.found.append(f"{self.where}:{getattr(node, 'lineno', '?')}: {what}: {_name(node)}")

    def _foreign(self, obj: ast.AST) -> bool:
        return not (isinstance(obj, ast.Name) and (obj.id == "self" or obj.id in self.own[-1]))

    def visit_FunctionDef(self, node: ast.FunctionDef | ast.AsyncFunctionDef) -> None:
        self.own.append(_made_here(node))
        self.generic_visit(node)
        self.own.pop()

    visit_AsyncFunctionDef = visit_FunctionDef

    def _targets(self, targets: list[ast.expr]) -> None:
        for tgt in targets:
            for node in ast.walk(tgt):
                if isinstance(node, ast.Subscript):
                    ns = _namespace_of(node.value)
                    if ns is not None and self._foreign(ns):
                        self._add(node, "write into another object's namespace")

    def visit_Assign(self, node: ast.Assign) -> None:
        self._targets(node.targets)
        self.generic_visit(node)

    def visit_AugAssign(self, node: ast.AugAssign) -> None:
        self._targets([node.target])
        self.generic_visit(node)

    def visit_Delete(self, node: ast.Delete) -> None:
        self._targets(node.targets)
        self.generic_visit(node)

    def visit_Call(self, node: ast.Call) -> None:
        f = node.func
        if isinstance(f, ast.Name) and f.id == "setattr" and node.args and self._foreign(node.args[0]):
            self._add(node, "setattr on another object")
        if _name(f) == "object.__setattr__" and node.args and self._foreign(node.args[0]):
            self._add(node, "object.__setattr__ on another object")
        if isinstance(f, ast.Attribute):
            ns = _namespace_of(f.value)
            if ns is not None and f.attr in DICT_WRITES and self._foreign(ns):
                self._add(node, "write into another object's namespace")
            if f.attr in KEY_CALLS and node.args and _dunder(node.args[0]) and _name(f.value) != "sys.modules":
                self._add(node, "dunder-shaped string key")
        self.generic_visit(node)

    def visit_Subscript(self, node: ast.Subscript) -> None:
        if _dunder(node.slice) and _name(node.value) != "sys.modules":
            self._add(node, "dunder-shaped string key")
        self.generic_visit(node)


def _dunder(node: ast.AST) -> bool:
    return isinstance(node, ast.Constant) and isinstance(node.value, str) and bool(DUNDER.match(node.value))


def reach_ins(source: str, where: str = "<text>") -> list[str]:
    """The reach-ins of one module's source, one line each (where: what: the expression)."""
    finder = _Finder(where)
    finder.visit(ast.parse(source))
    return finder.found


def package_reach_ins(root: Path = PACKAGE) -> list[str]:
    """The reach-ins of every module under ``root``."""
    found = []
    for path in sorted(root.rglob("*.py")):
        found += reach_ins(path.read_text(encoding="utf-8"), str(path.relative_to(root.parent)))
    return found


def test_the_package_keeps_no_state_on_other_objects():
    found = package_reach_ins()
    assert not found, "state kept on other objects (declare it on its owner):\n" + "\n".join(found)


@pytest.mark.parametrize("source", [
    'model.__dict__["_phi_last"] = (t, q)',
    'a = model.__dict__["_x"] = 1',
    'kp.__dict__.setdefault("_inputs", {})',
    'dep.__dict__.update(other)',
    'vars(model)["_x"] = 1',
    'vars(model).setdefault("_x", 1)',
    'del model.__dict__["_x"]',
    'setattr(model, "_x", 1)',
    'object.__setattr__(frozen, "_x", 1)',
    'prm.ts["__kernel__"] = kp',
    'hit = prm.ts.get("__kernel__")',
    'limit = params.ts["__drift_limit__"]',
    'def f(self, other):\n    other.__dict__["x"] = 1',
])
def test_each_kind_of_reach_in_is_found(source):
    assert len(reach_ins(source)) >= 1


@pytest.mark.parametrize("source", [
    'self.__dict__["_x"] = 1',
    'self.__dict__.setdefault("_x", {})',
    'setattr(self, "x", 1)',
    'd = {k: v for k, v in obj.__dict__.items()}',
    'main = sys.modules.get("__main__")',
    'if __name__ == "__main__":\n    pass',
    'def copy(p):\n    A = object.__new__(type(p))\n    A.__dict__.update(p.__dict__)\n    return A',
    'model.cache.solved = (t, s)',
    'prm.cache.kernels[lay] = kp',
])
def test_own_state_and_declared_caches_pass(source):
    assert reach_ins(source) == []
