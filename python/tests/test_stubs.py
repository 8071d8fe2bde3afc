"""The type stubs describe the module as it is: same names, same parameters."""

import ast
import inspect
import pathlib

import hexmss
from hexmss import _hexmss

STUB = pathlib.Path(hexmss.__file__).with_name("_hexmss.pyi")


def stub_tree():
    tree = ast.parse(STUB.read_text())
    functions, classes = {}, {}
    for node in tree.body:
        if isinstance(node, ast.FunctionDef):
            functions[node.name] = node
        elif isinstance(node, ast.ClassDef):
            members = {}
            for item in node.body:
                if isinstance(item, ast.FunctionDef):
                    members[item.name] = item
                elif isinstance(item, ast.AnnAssign):
                    members[item.target.id] = item
            classes[node.name] = members
    return functions, classes


def public(names):
    return {n for n in names if not n.startswith("_")}


def parameters(fn_node):
    a = fn_node.args
    names = [x.arg for x in a.posonlyargs + a.args + a.kwonlyargs]
    return [n for n in names if n not in ("self",)]


def test_every_module_name_is_in_the_stub_and_back():
    functions, classes = stub_tree()
    module = public(dir(_hexmss))
    assert module == public(functions) | public(classes)
    assert isinstance(_hexmss.__version__, str)


def test_every_class_member_is_in_the_stub_and_back():
    _, classes = stub_tree()
    for name, members in classes.items():
        cls = getattr(_hexmss, name)
        actual = public(dir(cls))
        assert actual == public(members), name


def test_parameters_match():
    functions, classes = stub_tree()
    checked = 0
    for name, node in functions.items():
        sig = inspect.signature(getattr(_hexmss, name))
        params = [p for p in sig.parameters if sig.parameters[p].kind != inspect.Parameter.VAR_KEYWORD]
        stub = parameters(node)
        # Keyword options forwarded to the scene schema (**kwargs in Rust)
        # are spelt out in the stub.
        assert stub[: len(params)] == params, name
        checked += 1
    for cname, members in classes.items():
        cls = getattr(_hexmss, cname)
        for mname, node in members.items():
            if not isinstance(node, ast.FunctionDef):
                continue
            if mname == "__init__":
                sig = inspect.signature(cls)
                params = [p for p in sig.parameters]
                assert parameters(node) == params, f"{cname}()"
                checked += 1
                continue
            if mname.startswith("__"):
                continue
            if any(isinstance(d, ast.Name) and d.id == "property" for d in node.decorator_list):
                continue
            obj = getattr(cls, mname)
            try:
                sig = inspect.signature(obj)
            except (TypeError, ValueError):
                continue
            params = [
                p
                for p, v in sig.parameters.items()
                if p != "self" and v.kind != inspect.Parameter.VAR_KEYWORD
            ]
            assert parameters(node)[: len(params)] == params, f"{cname}.{mname}"
            checked += 1
    assert checked > 30
