"""Every public function documents every parameter (python-control's docstring discipline)."""

from __future__ import annotations

import importlib
import inspect
import pkgutil
import re

import pytest

import gcs

SKIP_PARAMS = {"self", "cls"}


def _public_modules() -> list[str]:
    names = []
    for info in pkgutil.walk_packages(gcs.__path__, "gcs."):
        if info.name.endswith("__main__"):
            continue
        module = importlib.import_module(info.name)
        if hasattr(module, "__all__"):
            names.append(info.name)
    return names


def _callables(module_name: str):
    module = importlib.import_module(module_name)
    for name in module.__all__:
        obj = getattr(module, name)
        if inspect.isfunction(obj):
            yield f"{module_name}.{name}", obj
        elif inspect.isclass(obj):
            for attr, member in vars(obj).items():
                if inspect.isfunction(member) and not attr.startswith("_"):
                    yield f"{module_name}.{name}.{attr}", member


def _documented(doc: str, param: str) -> bool:
    # numpydoc: "name : type" or "a, b : type" at the start of a line
    pattern = rf"^\s*(\w+\s*,\s*)*{re.escape(param)}(\s*,\s*\w+)*\s*(:|$)"
    return re.search(pattern, doc, re.MULTILINE) is not None


CASES = [case for module in _public_modules() for case in _callables(module)]


def test_there_are_public_functions_to_check() -> None:
    assert len(CASES) > 30


@pytest.mark.parametrize(("name", "func"), CASES, ids=[c[0] for c in CASES])
def test_public_function_documents_its_parameters(name: str, func) -> None:
    doc = inspect.getdoc(func)
    assert doc, f"{name} has no docstring"
    params = [
        p
        for p in inspect.signature(func).parameters.values()
        if p.name not in SKIP_PARAMS and p.kind not in (p.VAR_POSITIONAL, p.VAR_KEYWORD)
    ]
    missing = [p.name for p in params if not _documented(doc, p.name)]
    assert not missing, f"{name}: parameters not documented: {missing}"
