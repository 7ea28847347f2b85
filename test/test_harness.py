"""The test harness itself: under the README's test command (``tools/test.sh`` sets LOCEM_NO_SKIP=1) a skipped
test fails the run, unless the platform forces the skip (reason starting with ``platform:``).

Runs a real pytest in a subprocess on a small test folder that uses this project's own ``test/conftest.py``.
"""
import os
import shutil
import subprocess
import sys

HERE = os.path.dirname(os.path.abspath(__file__))

TESTS = '''
import pytest
missing = pytest.importorskip("a_module_that_is_not_installed_anywhere")
'''

RUNTIME = '''
import pytest

def test_passes():
    assert 1 + 1 == 2

@pytest.mark.skipif(True, reason="platform: this OS has no such device")
def test_platform_skip():
    pass

def test_broken_setup():
    pytest.skip("needs the environment of tools/test.sh")
'''


def run_pytest(folder, strict):
    env = dict(os.environ)
    env.pop("LOCEM_NO_SKIP", None)
    if strict:
        env["LOCEM_NO_SKIP"] = "1"
    done = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "-c", os.devnull,
                           "--rootdir", str(folder), str(folder)], cwd=str(folder), env=env,
                          stdout=subprocess.PIPE, stderr=subprocess.STDOUT, universal_newlines=True, timeout=120)
    return done.returncode, done.stdout


def make_folder(tmp_path):
    shutil.copy(os.path.join(HERE, "conftest.py"), str(tmp_path / "conftest.py"))
    (tmp_path / "test_collect.py").write_text(TESTS)
    (tmp_path / "test_runtime.py").write_text(RUNTIME)
    return tmp_path


def test_skips_are_refused_under_the_readme_test_command(tmp_path):
    code, out = run_pytest(make_folder(tmp_path), strict=True)
    assert code == 1, out
    assert "skips refused" in out, out
    assert "test_runtime.py::test_broken_setup: " in out and "needs the environment of tools/test.sh" in out, out
    assert "a_module_that_is_not_installed_anywhere" in out, out          # a module-level importorskip too
    assert "test_platform_skip" not in out.split("skips refused")[1], out  # the platform's own skip is allowed
    assert "2 skipped test(s) counted as failures" in out, out


def test_plain_pytest_keeps_ordinary_skips(tmp_path):
    code, out = run_pytest(make_folder(tmp_path), strict=False)
    assert code == 0, out
    assert "skips refused" not in out, out
    assert "1 passed, 3 skipped" in out, out
