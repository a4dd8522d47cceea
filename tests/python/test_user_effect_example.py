"""docs/examples/user_effect.py, the Python worked example, runs and ends as documented."""
import os
import subprocess
import sys


def test_user_effect_example_runs():
    src = os.environ.get("CDM_SOURCE_DIR", os.path.join(os.path.dirname(__file__), "..", ".."))
    script = os.path.join(src, "docs", "examples", "user_effect.py")
    r = subprocess.run([sys.executable, script, "--check"], capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stdout + r.stderr
    assert "with worn_spot: explained = True" in r.stdout
