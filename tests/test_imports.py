"""hexa_mjx's import hooks: old module names still run, and the hooks import nothing themselves."""

import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def run_python(code):
    return subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=120)


def test_hooks_import_nothing_while_finding():
    # Python 3.12 starts without importlib.machinery loaded: a finder that imports it while finding
    # a module is asked to find it again, without end. Dropping it here makes 3.11 do the same.
    out = run_python("import sys, hexa_mjx\n"
                     "for name in ('importlib.machinery', 'importlib.util'): sys.modules.pop(name, None)\n"
                     "import json.tool\n"
                     "print('imported')")
    assert out.returncode == 0 and "imported" in out.stdout, out.stderr[-2000:]


def test_old_module_name_runs_the_moved_module():
    out = subprocess.run([sys.executable, "-m", "hexa_mjx.time_to_success", "--help"], cwd=ROOT,
                         capture_output=True, text=True, timeout=120)
    assert out.returncode == 0 and "usage: " in out.stdout, out.stderr[-2000:]
