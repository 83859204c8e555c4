"""The package surface: lazy top-level names and the README's code run as written."""

from __future__ import annotations

import os
import re
import types

import pytest

import nurbskit

from conftest import REPO_ROOT


@pytest.mark.parametrize("name", sorted(nurbskit._LAZY))
def test_lazy_names_resolve(name):
    module_name, attribute = nurbskit._LAZY[name]
    value = getattr(nurbskit, name)
    if attribute is None:
        assert isinstance(value, types.ModuleType) and value.__name__ == module_name
    else:
        assert callable(value) and not isinstance(value, types.ModuleType)
        assert value.__module__ == module_name or value.__module__.startswith(module_name + ".")


def test_unknown_name_raises_attribute_error():
    with pytest.raises(AttributeError):
        nurbskit.no_such_thing  # noqa: B018


def test_readme_python_example_runs(tmp_path):
    text = (REPO_ROOT / "README.md").read_text()
    blocks = re.findall(r"```python\n(.*?)```", text, flags=re.S)
    assert blocks, "README has no python example"
    cwd = os.getcwd()
    os.chdir(tmp_path)
    try:
        for block in blocks:
            exec(compile(block, "README.md", "exec"), {})
    finally:
        os.chdir(cwd)
    assert (tmp_path / "surface.json").exists()
