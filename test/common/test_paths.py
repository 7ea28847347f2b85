"""common/paths: the package's files are found one way, and helper processes import the parent's code."""
import os
import re
import subprocess
import sys

from locem_bridge.common.paths import PYTHON_ROOT, checkout_root, child_env

PACKAGE = os.path.join(PYTHON_ROOT, "locem_bridge")


def test_the_roots_hold_the_package_and_its_shipped_configuration():
    assert os.path.isfile(os.path.join(PACKAGE, "__init__.py"))
    for sub in ("config/robots/rbkairos_ur10e.yaml", "config/sites/default.yaml", "config/hicem/plasterboard.yaml",
                "trees", "ontologies"):
        assert os.path.exists(os.path.join(checkout_root(), sub)), sub


def test_a_helper_process_imports_the_same_package_whatever_its_environment_holds(tmp_path):
    decoy = tmp_path / "locem_bridge"          # a stale copy first on the caller's PYTHONPATH must not win
    decoy.mkdir()
    (decoy / "__init__.py").write_text("raise ImportError('decoy package imported')\n")
    env = child_env({"PATH": os.environ.get("PATH", ""), "PYTHONPATH": str(tmp_path)})
    assert env["PYTHONPATH"].split(os.pathsep) == [PYTHON_ROOT, str(tmp_path)]
    out = subprocess.run([sys.executable, "-c", "import locem_bridge, os; print(os.path.dirname(locem_bridge.__file__))"],
                         env=env, cwd=str(tmp_path.parent), capture_output=True, text=True, timeout=60)
    assert out.returncode == 0, out.stderr
    assert os.path.samefile(out.stdout.strip(), PACKAGE)


def test_no_other_module_climbs_from_its_own_file_to_find_the_package():
    climb = re.compile(r"dirname\(\s*os\.path\.dirname\(.*__file__|__file__.*[\"']\.\.[\"']")
    found = []
    for folder, dirs, files in os.walk(PACKAGE):
        dirs[:] = [d for d in dirs if d != "__pycache__"]
        for name in files:
            path = os.path.join(folder, name)
            if not name.endswith(".py") or path == os.path.join(PACKAGE, "common", "paths.py"):
                continue
            with open(path, encoding="utf-8") as handle:
                found += ["%s:%d" % (os.path.relpath(path, PACKAGE), i) for i, line in enumerate(handle, 1)
                          if climb.search(line)]
    assert not found, "use locem_bridge.common.paths instead of climbing from __file__: %s" % ", ".join(found)
