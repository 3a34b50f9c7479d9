"""The package's shape: type stubs that name what the native module has, docstrings."""

from __future__ import annotations

import ast
from pathlib import Path

import magic
import magic.xarray
from magic import _magic


def test_stubs_name_what_the_module_has():
    stub = Path(_magic.__file__).with_name("_magic.pyi")
    tree = ast.parse(stub.read_text())
    names = set()
    for node in tree.body:
        if isinstance(node, (ast.FunctionDef, ast.ClassDef)):
            names.add(node.name)
            assert hasattr(_magic, node.name), node.name
        if isinstance(node, ast.ClassDef):
            members = {n.name for n in node.body if isinstance(n, ast.FunctionDef)}
            cls = getattr(_magic, node.name)
            missing = [m for m in members if not hasattr(cls, m)]
            assert not missing, (node.name, missing)
        if isinstance(node, ast.AnnAssign):
            names.add(node.target.id)
            assert hasattr(_magic, node.target.id), node.target.id
    public = {n for n in dir(_magic) if not n.startswith("__") or n == "__version__"}
    assert public <= names | {"_magic"}, public - names


def test_docstrings():
    for obj in (magic, magic.Model, magic.Model.invert, magic.Model.load, magic.Tables,
                magic.Tables.load, magic.mogi.forward, magic.inform.forward,
                magic.prosail.forward):
        assert obj.__doc__ and len(obj.__doc__) > 40, obj
    assert "apply_ufunc" in magic.xarray.__doc__
    assert "Returns" in magic.xarray.invert.__doc__
