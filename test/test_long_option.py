"""The ``--long`` option of this project's ``test/conftest.py``: a test marked ``long`` is skipped with a reason
saying how to run it (and that skip is not refused under the README's test command, which refuses other skips);
given ``--long``, it runs.

Runs a real pytest in a subprocess on a small test folder that uses this project's own ``test/conftest.py``.
"""
import os
import shutil
import subprocess
import sys

HERE = os.path.dirname(os.path.abspath(__file__))

TESTS = '''
import pytest

def test_quick():
    pass

@pytest.mark.long
def test_minutes():
    print("the long test ran")

@pytest.mark.long
@pytest.mark.parametrize("seed", [1, 2])
def test_minutes_per_seed(seed):
    pass
'''


def run_pytest(folder, *args, strict=True):
    env = dict(os.environ)
    env.pop("LOCEM_NO_SKIP", None)
    if strict:
        env["LOCEM_NO_SKIP"] = "1"                     # as tools/test.sh sets it
    done = subprocess.run([sys.executable, "-m", "pytest", "-q", "-rs", "-s", "-p", "no:cacheprovider", "-c",
                           os.devnull, "--rootdir", str(folder), str(folder)] + list(args), cwd=str(folder), env=env,
                          stdout=subprocess.PIPE, stderr=subprocess.STDOUT, universal_newlines=True, timeout=120)
    return done.returncode, done.stdout


def make_folder(tmp_path):
    shutil.copy(os.path.join(HERE, "conftest.py"), str(tmp_path / "conftest.py"))
    (tmp_path / "test_some.py").write_text(TESTS)
    return tmp_path


def test_long_tests_are_skipped_with_how_to_run_them_and_the_strict_run_stays_green(tmp_path):
    code, out = run_pytest(make_folder(tmp_path))
    assert code == 0, out
    assert "1 passed, 3 skipped" in out, out
    assert "skips refused" not in out, out
    assert "long: takes minutes; run with --long (bash tools/test.sh --long)" in out, out
    assert "the long test ran" not in out, out


def test_long_runs_them(tmp_path):
    code, out = run_pytest(make_folder(tmp_path), "--long")
    assert code == 0, out
    assert "4 passed" in out and "skipped" not in out, out
    assert "the long test ran" in out, out


def test_the_option_is_listed_in_the_help(tmp_path):
    code, out = run_pytest(make_folder(tmp_path), "--help", strict=False)
    assert code == 0, out
    assert "--long" in out and "also run the tests marked long" in out, out
