"""Test command for the mutation check: run the fast tests of the module cosmic-ray mutated.

cosmic-ray edits one source file in place and runs this script; ``git diff`` names that file,
and :data:`_TESTS` maps a keyword of its path to the test files that exercise it (first match
wins). Exit status 0 means every selected test passed (the mutant survived).
"""

from __future__ import annotations

import subprocess
import sys

#: (keyword in the mutated file's path, test files); first match wins; works on the flat
#: realise/ layout (9899009) and on the one-folder-per-realisation layout
_TESTS: list[tuple[str, list[str]]] = [
    ("mesh", ["test_mesh_response.py", "test_mesh_dynamics.py", "test_mesh_fit.py", "test_mesh_spice.py",
              "test_mesh_differentiable.py", "test_realisation_contract.py"]),
    ("asic", ["test_asic.py", "test_asic_rtl.py", "test_asic_differentiable.py", "test_realisation_contract.py"]),
    ("metalens", ["test_metalens.py", "test_metalens_differentiable.py", "test_realisation_contract.py"]),
    ("optics", ["test_optics.py", "test_metalens.py"]),
    ("spectral", ["test_metalens.py", "test_optics.py"]),
    ("realise/", ["test_realise_base.py", "test_optics.py", "test_realisation_contract.py"]),
    ("design/", ["test_explore_design.py", "test_validation.py", "test_inputs_safety.py"]),
    ("explore/sweep", ["test_explore_sweep.py"]),
    ("explore/store", ["test_explore_sweep.py", "test_explore_paired.py"]),
    ("explore/emulation", ["test_explore_emulation.py", "test_explore_emulation_track.py"]),
    ("studies/kernel_size_ablation", ["test_tasks_ablation.py"]),
    ("explore/sizing", ["test_stats.py"]),
    ("explore/paired", ["test_explore_paired.py", "test_stats.py"]),
    ("explore/scoring", ["test_explore_paired.py", "test_explore_emulation_track.py", "test_report.py",
                         "test_explore_sweep.py", "test_records.py", "test_realisation_contract.py"]),
    ("explore/", ["test_explore_design.py", "test_explore_paired.py"]),
    ("studies/", ["test_explore_design.py", "test_explore_paired.py"]),  # as when they lived in explore/
]


def _mutated() -> list[str]:
    out = subprocess.run(["git", "diff", "--name-only", "--", "fsdvs_hw"], capture_output=True,
                         text=True, check=True).stdout
    return [line for line in out.splitlines() if line.endswith(".py")]


def main() -> int:
    files = _mutated()
    tests: list[str] = []
    for path in files or [""]:
        for key, names in _TESTS:
            if key in path:
                tests += [f"tests/{n}" for n in names if f"tests/{n}" not in tests]
                break
    if not tests:
        tests = ["tests/test_realise_base.py", "tests/test_explore_design.py"]
    cmd = [sys.executable, "-m", "pytest", "-x", "-q", "-m", "not slow", "-p", "no:cacheprovider", *tests]
    print("mutated:", files, "->", " ".join(tests), flush=True)
    return subprocess.run(cmd).returncode


if __name__ == "__main__":
    sys.exit(main())
