"""The examples as a user runs them (``python examples/x.py``, a fresh process): quiet, as the CLI
is. Issue 34 found Warp's banner, its no-CUDA-driver warning and "Module ... (cached)" lines mixed
into the examples' output."""

import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
SHARED = REPO.parent / "shared" / "data"
# Lines Warp prints that a user of the examples should not see.
WARP_NOISE = ("Warp ", "Module ", "   Devices:", "   Kernel cache:", "CUDA Toolkit")

EXAMPLES = {
    "stochastic_plane.py": ["--resolution", "24x32"],
    "triplanar_bunny.py": ["--resolution", "24x32"],
    "fit_splat.py": ["--iters", "2"],
    "torch_fit.py": ["--iters", "2"],
}


@pytest.mark.parametrize("script", list(EXAMPLES))
def test_examples_print_only_their_own_lines(script, tmp_path):
    if script == "torch_fit.py":
        pytest.importorskip("torch", reason="PyTorch is not installed (pip install torch)")
    if script in ("stochastic_plane.py", "triplanar_bunny.py") and not SHARED.is_dir():
        pytest.skip(f"{SHARED} not found: this example reads the shared data by default")
    done = subprocess.run([sys.executable, str(REPO / "examples" / script), *EXAMPLES[script], "--out", str(tmp_path)],
                          cwd=tmp_path, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr
    noise = [line for line in (done.stdout + done.stderr).splitlines() if line.lstrip().startswith(WARP_NOISE) or "CUDA warning" in line]
    assert not noise, noise
    assert "wrote " in done.stdout
