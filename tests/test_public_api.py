"""The public names: lazily loaded at run time, and the same names imported for static tools."""

from __future__ import annotations

import ast
import importlib
import subprocess
import sys
from pathlib import Path

import pytest

PKG = Path(__file__).resolve().parents[1] / "fsdvs_hw"


@pytest.mark.parametrize("package", ["fsdvs_hw", "fsdvs_hw.tasks", "fsdvs_hw.sensor"])
def test_type_checking_imports_list_exactly_the_lazy_names_and_each_resolves(package):
    path = PKG / ("__init__.py" if package == "fsdvs_hw" else f"{package.split('.')[1]}/__init__.py")
    tree = ast.parse(path.read_text())

    def assigns_lazy(node: ast.stmt) -> bool:
        targets = node.targets if isinstance(node, ast.Assign) else [getattr(node, "target", None)]
        return any(isinstance(t, ast.Name) and t.id == "_LAZY" for t in targets)

    lazy = next(
        ast.literal_eval(n.value) for n in tree.body if isinstance(n, (ast.Assign, ast.AnnAssign)) and assigns_lazy(n)
    )
    block = next(n for n in tree.body if isinstance(n, ast.If) and ast.unparse(n.test) == "TYPE_CHECKING")
    static = {a.name: ("." * imp.level + (imp.module or "")) for imp in block.body for a in imp.names}
    assert set(static) == set(lazy)
    for name, module in lazy.items():  # each static import names the module the lazy table names
        assert module.endswith(static[name].lstrip(".")), (name, module, static[name])
    mod = importlib.import_module(package)
    assert set(lazy) <= set(mod.__all__) == set(dir(mod))
    for name in lazy:
        assert getattr(mod, name) is getattr(importlib.import_module(lazy[name]), name)
    with pytest.raises(AttributeError, match="has no attribute 'no_such_name'"):
        getattr(mod, "no_such_name")


def test_importing_the_package_does_not_import_torch_or_casadi():
    code = "import sys, fsdvs_hw, fsdvs_hw.tasks; print('torch' in sys.modules, 'casadi' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout.split()
    assert out == ["False", "False"]


def test_the_simulate_command_line_is_parsed_without_torch():
    """Parsing ``fsdvs-hw simulate`` (presets, input mappings, upsampling modes) and reading a
    preset and its mapping load no torch: a bad argument is refused at once, and the command's
    own imports start only once its arguments hold."""
    code = (
        "import sys; from fsdvs_hw.cli import _parser; "
        "_parser('simulate').parse_args(['simulate', 'example:bikes', '--out', 'e.h5']); "
        "from fsdvs_hw.sensor.simulation.config import SensorConfig; from fsdvs_hw.sensor.cameras.presets import preset_input_mapping; "
        "SensorConfig.preset('v2e-default'); preset_input_mapping('v2e-default'); "
        "print('torch' in sys.modules)"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout.split()
    assert out == ["False"]


def test_the_simulator_loads_without_pydantic():
    """pydantic (about 0.2 s to import) serves the design files and fit options; the simulator's own
    argument checks (``fsdvs_hw.validation``) and the ``simulate`` command do not load it."""
    code = (
        "import sys, fsdvs_hw.sensor.simulation.stream, fsdvs_hw.sensor.eventfiles.eventfile, fsdvs_hw.cli.simulate, fsdvs_hw.validation; "
        "print('pydantic' in sys.modules)"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout.split()
    assert out == ["False"]
