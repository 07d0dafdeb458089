"""The command line as a user meets it: a checkout that imports, --version, one-line errors that
name the input and write nothing, Ctrl-C, atomic output sets."""

import gc
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import trimesh
import warp as wp

import warptex as wt
from warptex import io
from warptex import _output as output
from warptex.apps.cli import main

ROOT = Path(__file__).resolve().parents[1]
RENDER_FILES = ["albedo.png", "gbuffer.exr", "normals.png", "render.exr", "render.png"]
SMALL = ["--resolution", "24x32"]


def _python(code: str, cwd: Path) -> subprocess.CompletedProcess:
    """``python -c code`` in ``cwd`` with this checkout first on the path and any editable-install
    finder removed: the import a source checkout gets, installed or not."""
    prelude = (
        "import sys; "
        "sys.meta_path[:] = [f for f in sys.meta_path if 'editable' not in repr(f).lower()]; "
        f"sys.path.insert(0, {str(ROOT)!r}); "
    )
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    return subprocess.run([sys.executable, "-c", prelude + code], cwd=cwd, env=env, capture_output=True, text=True, timeout=300)


def test_a_checkout_imports_its_kernels(tmp_path):
    done = _python("import warptex, warptex.kernels.sampling as ks; print(warptex.__file__); print(ks.__file__)", tmp_path)
    assert done.returncode == 0, done.stderr
    package, kernels = done.stdout.split()
    assert Path(package) == ROOT / "warptex" / "__init__.py"
    assert Path(kernels) == ROOT / "kernels" / "sampling.py"


def test_python_m_warptex_prints_its_version_without_warp_noise(tmp_path):
    done = _python("import runpy, sys; sys.argv = ['warptex', '--version']; runpy.run_module('warptex', run_name='__main__')", tmp_path)
    assert done.returncode == 0, done.stderr
    assert done.stdout.startswith("warptex 0.") and "warp-lang" in done.stdout
    assert done.stderr == ""


def test_cli_errors_are_one_line_without_warp_start_up_noise(tmp_path):
    done = _python(f"import sys; from warptex.apps.cli import main; sys.exit(main(['--out', {str(tmp_path / 'out')!r}, '--mesh', {str(tmp_path)!r}]))", tmp_path)
    assert done.returncode == 1
    assert done.stderr.splitlines() == [f"warptex: error: load_mesh(): {str(tmp_path)!r} is a folder, not a mesh file"]
    assert done.stdout == "" and not (tmp_path / "out").exists()


COLLECTOR_SEEN = """
import gc, sys
import warptex.apps.render as render
from warptex.apps import cli
run = render.run_render
render.run_render = lambda *a, **k: (print("collector", gc.isenabled(), gc.get_freeze_count() > 0), run(*a, **k))[1]
sys.argv = ["warptex", "render", "--resolution", "16x16", "--out", sys.argv[1]]
cli.entry()
"""


def test_the_command_runs_its_job_with_the_collector_on_and_leaves_a_callers_alone(tmp_path):
    """The process's entry pauses Python's cycle collector through the imports and turns it back
    on, the imports' objects frozen, before the job runs (a fit's loop must not keep its cyclic
    garbage); :func:`main` called in a program leaves that program's collector as it was."""
    done = _python(COLLECTOR_SEEN.replace("sys.argv[1]", repr(str(tmp_path / "out"))), tmp_path)
    assert done.returncode == 0, done.stderr
    assert "collector True True" in done.stdout.splitlines(), done.stdout
    frozen = gc.get_freeze_count()
    assert main(["render", *SMALL, "--out", str(tmp_path / "in_process")]) == 0
    assert gc.isenabled() and gc.get_freeze_count() == frozen


def _obj(path: Path, text: str) -> Path:
    path.write_text(text)
    return path


@pytest.mark.parametrize(
    "name, text, message",
    [
        ("empty.obj", "# nothing here\n", "holds no vertices and no faces; warptex renders triangle meshes"),
        ("nan.obj", "v 0 0 0\nv 1 0 0\nv 0 nan 1\nf 1 2 3\n", "vertex 2 is not finite"),
        ("points.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\n", "holds 3 vertices and no faces; warptex renders triangle meshes"),
        # issue 34: a NaN UV was found only when write_png refused the NaN image, leaving an empty folder
        ("nan_uv.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nvt nan 0\nvt 1 0\nvt 0 1\nf 1/1 2/2 3/3\n",
         "UV set 'uv0' is not finite at 1 vertices, e.g. vertex 0: [nan, 0.0]"),
        ("text.glb", "this is a text file, not a binary glTF\n", "is not a binary glTF (.glb) file: it starts with b'this', a .glb file with b'glTF'"),
    ],
)
def test_a_bad_mesh_is_named_before_the_camera_is_framed(tmp_path, capsys, name, text, message):
    path = _obj(tmp_path / name, text)
    out = tmp_path / "out"
    assert main(["--out", str(out), "--mesh", str(path), *SMALL]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith(f"warptex: error: load_mesh(): {str(path)!r}") and message in err[0], err
    assert not out.exists()


def test_a_truncated_exr_texture_is_a_clear_error(tmp_path, capsys):
    io.write_exr(tmp_path / "whole.exr", np.random.default_rng(0).random((32, 32, 3)).astype(np.float32))
    cut = tmp_path / "cut.exr"
    cut.write_bytes((tmp_path / "whole.exr").read_bytes()[:400])
    mesh = _obj(tmp_path / "tri.obj", "v 0 0 0\nv 1 0 0\nv 0 0 1\nf 1 3 2\n")
    assert main(["--out", str(tmp_path / "out"), "--mesh", str(mesh), "--texture", str(cut), *SMALL]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith(f"warptex: error: read_texels(): cannot decode '{cut}'"), err  # what from_file reads with
    assert not (tmp_path / "out").exists()


def test_a_memory_budget_beyond_memory_is_refused_up_front(tmp_path, capsys, monkeypatch):
    """A render is made in bands of at most --memory: a picture of any size fits, a budget past
    the machine's memory is refused before any work."""
    monkeypatch.setattr(output, "_available_memory", lambda: 2 * 2**30)
    assert main(["--out", str(tmp_path / "out"), "--resolution", "100000x100000", "--memory", "3GiB"]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert err == ["warptex: error: run_render(): a 100000x100000 render of 4 samples per pixel needs about 3.4 GiB of memory, but 2.0 GiB is available; use a smaller --memory"]
    assert main(["fit", "--out", str(tmp_path / "out"), "--resolution", "20000x20000"]) == 1
    assert "run_fit(): a fit of 2 20000x20000 view(s) needs about" in capsys.readouterr().err
    assert not (tmp_path / "out").exists()


def test_failed_allocations_are_reported_not_raised(tmp_path, capsys, monkeypatch):
    import warptex.apps.render as render

    def fail(*args, **kwargs):
        raise RuntimeError("Failed to allocate 8000000000 bytes on device 'cpu'")

    monkeypatch.setattr(render, "gbuffer_tiles", fail)
    assert main(["--out", str(tmp_path / "out"), *SMALL]) == 1
    assert capsys.readouterr().err.strip() == "warptex: error: out of memory: Failed to allocate 8000000000 bytes on device 'cpu'"
    monkeypatch.setattr(render, "gbuffer_tiles", lambda *a, **k: (_ for _ in ()).throw(RuntimeError("a bug")))
    with pytest.raises(RuntimeError, match="a bug"):  # anything else is a bug and keeps its traceback
        main(["--out", str(tmp_path / "out"), *SMALL])


@pytest.mark.parametrize(
    "args, message",
    [
        (["--tiling", "nan"], "argument --tiling: must be a finite number > 0"),
        (["--tiling", "0"], "argument --tiling: must be a finite number > 0"),
        (["--fov", "180"], "argument --fov: must be a finite number > 0 and < 180"),
        (["--eye=1,inf,2"], "argument --eye: expected three finite numbers"),
        (["fit", "--iters", "0"], "argument --iters: must be at least 1"),
        (["fit", "--report-every", "-1"], "argument --report-every: must be at least 0"),
    ],
)
def test_options_out_of_range_are_refused_by_the_parser(tmp_path, capsys, args, message):
    with pytest.raises(SystemExit) as info:
        main([*args, "--out", str(tmp_path / "out")])
    assert info.value.code == 2 and message in capsys.readouterr().err
    assert not (tmp_path / "out").exists()


def test_fit_checks_map_sizes_before_writing_anything(tmp_path, capsys):
    out = tmp_path / "out"
    assert main(["fit", "--out", str(out), "--iters", "2", "--map-size", "2x2", *SMALL]) == 1
    assert "scored against the true 129x129 splat maps, so the fitted maps must be that size too, got 2x2" in capsys.readouterr().err
    io.write_exr(tmp_path / "a.exr", np.full((129, 129, 4), 0.25, np.float32))
    io.write_exr(tmp_path / "b.exr", np.full((65, 65, 4), 0.25, np.float32))
    assert main(["fit", "--out", str(out), "--iters", "2", "--initial-maps", str(tmp_path / "a.exr"), str(tmp_path / "b.exr"), *SMALL]) == 1
    assert "must share one size and channel count, got a.exr: 129x129x4, b.exr: 65x65x4" in capsys.readouterr().err
    assert not out.exists()


def test_a_huge_tiling_renders_finite_colours(tmp_path):
    assert main(["--out", str(tmp_path), "--tiling", "1e30", *SMALL]) == 0
    assert np.isfinite(io.read_image(tmp_path / "render.exr")).all()


def test_ctrl_c_is_one_line_exit_130_and_keeps_the_previous_files(tmp_path, capsys, monkeypatch):
    assert main(["--out", str(tmp_path), *SMALL]) == 0
    before = {name: (tmp_path / name).read_bytes() for name in RENDER_FILES}
    capsys.readouterr()
    import warptex.apps.render as render

    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(render.GBufferWriter, "write", interrupted)  # the last file of the first band: the others have rows by then
    assert main(["--out", str(tmp_path), "--seed", "5", *SMALL]) == 130
    captured = capsys.readouterr()
    assert captured.err.strip() == "warptex: interrupted; no files were written" and "wrote" not in captured.out
    assert sorted(os.listdir(tmp_path)) == RENDER_FILES
    assert {name: (tmp_path / name).read_bytes() for name in RENDER_FILES} == before


def test_a_killed_runs_staging_folder_is_removed_by_the_next(tmp_path):
    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()
    stale = tmp_path / f".warptex-{dead.pid}-0badc0de.partial"
    stale.mkdir()
    (stale / "render.exr").write_bytes(b"x" * 4096)
    live = tmp_path / f".warptex-{os.getppid()}-0badc0de.partial"  # a run still going: kept
    live.mkdir()
    assert main(["--out", str(tmp_path), *SMALL]) == 0
    assert sorted(os.listdir(tmp_path)) == sorted([live.name, *RENDER_FILES])


def test_output_set_moves_files_only_when_all_are_written(tmp_path):
    (tmp_path / "a.txt").write_text("old a")
    with pytest.raises(ValueError):
        with output.output_set(tmp_path) as staging:
            (staging / "a.txt").write_text("new a")
            raise ValueError("the second file failed")
    assert os.listdir(tmp_path) == ["a.txt"] and (tmp_path / "a.txt").read_text() == "old a"
    with output.output_set(tmp_path / "new") as staging:
        (staging / "a.txt").write_text("new a")
        (staging / "b.txt").write_text("new b")
    assert sorted(os.listdir(tmp_path / "new")) == ["a.txt", "b.txt"]
    with pytest.raises(OSError, match="is a file"):
        with output.output_set(tmp_path / "a.txt"):
            pass


def test_an_output_folder_that_is_a_file_is_refused_before_the_work(tmp_path, capsys, monkeypatch):
    import warptex.apps.render as render

    monkeypatch.setattr(render, "gbuffer_tiles", None)  # would fail if the render started
    (tmp_path / "out").write_text("a file")
    assert main(["--out", str(tmp_path / "out"), *SMALL]) == 1
    assert capsys.readouterr().err.strip() == f"warptex: error: run_render(): the output folder {str(tmp_path / 'out')!r} is a file"


def test_an_output_folder_that_cannot_be_made_is_named_up_front(tmp_path, capsys):
    """Issue 34: ``--out /proc/nope`` printed a bare ``[Errno 2]``. The folder is tried before
    the work, and whatever the probe made is removed again."""
    locked = tmp_path / "file"
    locked.write_text("")
    assert main(["--out", str(locked / "sub"), *SMALL]) == 1
    assert capsys.readouterr().err.strip() == f"warptex: error: run_render(): cannot write into the output folder {str(locked / 'sub')!r}: Not a directory"
    if Path("/proc/self").exists():
        assert main(["--out", "/proc/nope", *SMALL]) == 1
        err = capsys.readouterr().err.strip()
        assert err.startswith("warptex: error: run_render(): cannot write into the output folder '/proc/nope': ") and "Errno" not in err, err
    assert main(["--out", str(tmp_path / "a" / "b"), "--mesh", str(tmp_path / "missing.obj"), *SMALL]) == 1
    capsys.readouterr()
    assert not (tmp_path / "a").exists()  # the probe's folders are gone


@pytest.mark.skipif(wp.get_cuda_device_count() > 0, reason="a CUDA device is present: cuda:0 exists")
def test_a_missing_cuda_device_says_which_devices_there_are(tmp_path, capsys):
    for command in ([], ["demo"]):
        assert main([*command, "--out", str(tmp_path / "out"), "--device", "cuda:0", *SMALL]) == 1
        err = capsys.readouterr().err.strip()
        assert err == "warptex: error: --device: device 'cuda:0' does not exist: no CUDA device is available here; the devices are cpu", err
    assert not (tmp_path / "out").exists()
    with pytest.raises(ValueError, match=r"rasterize\(\): device 'cuda:0' does not exist: no CUDA device is available here"):
        wt.rasterize(trimesh.creation.box(), wt.look_at((0, 0, 5), (0, 0, 0), resolution=(8, 8)), device="cuda:0")


def test_a_top_down_view_and_an_eye_typed_with_a_space(tmp_path, monkeypatch):
    """Issue 34: ``--eye 0,10,0 --target 0,0,0`` failed (up parallel to the view) and
    ``--eye -30,25,40`` (a space, not ``=``) failed with "expected one argument"."""
    import warptex.apps.render as render

    cameras = []
    real = render.gbuffer_tiles
    monkeypatch.setattr(render, "gbuffer_tiles", lambda mesh, camera, **kw: cameras.append(camera) or real(mesh, camera, **kw))
    assert main(["--out", str(tmp_path / "top"), "--eye", "0,10,0", "--target", "0,0,0", *SMALL]) == 0
    np.testing.assert_allclose(cameras[-1].up, [0, 0, -1], atol=1e-12)
    assert main(["render", "--out", str(tmp_path / "space"), "--eye", "-30,25,40", "--target", "-1.5,0,0", *SMALL]) == 0
    np.testing.assert_allclose(cameras[-1].eye, [-30, 25, 40])
    assert main(["--out", str(tmp_path / "up"), "--eye", "0,10,0", "--target", "0,0,0", "--up", "1,0,0", *SMALL]) == 0
    np.testing.assert_allclose(cameras[-1].up, [1, 0, 0], atol=1e-12)


def test_tiling_help_says_what_it_means_for_each_kind_of_mesh(capsys):
    with pytest.raises(SystemExit):
        main(["render", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    for case in ("Default terrain: layer repeats per world unit (default 1/6", "A mesh with UVs: repeats across UV0",
                 "A mesh without UVs (mapped triplanar): repeats across the mesh's largest extent (default 8)"):
        assert case in text, case


def test_the_layer_of_an_exr_texture_is_chosen_on_the_command_line(tmp_path, capsys):
    planes = {f"{layer}.{c}": np.full((8, 8), v, np.float32) for layer, v in (("diffuse", 0.8), ("specular", 0.1)) for c in "RGB"}
    io.write_exr(tmp_path / "layers.exr", planes)
    mesh = _obj(tmp_path / "tri.obj", "v -1 -1 0\nv 1 -1 0\nv 0 1 0\nf 1 2 3\n")
    args = ["--mesh", str(mesh), "--texture", str(tmp_path / "layers.exr"), "--eye", "0,0,3", "--target", "0,0,0", *SMALL]
    assert main(["--out", str(tmp_path / "none"), *args]) == 1
    assert "holds several layers ['diffuse', 'specular'] and no default one; choose one with layer= (warptex render: --texture-layer)" in capsys.readouterr().err
    assert main(["--out", str(tmp_path / "out"), *args, "--texture-layer", "specular"]) == 0
    albedo = io.read_image(tmp_path / "out" / "albedo.png")
    centre = albedo[12, 16]
    np.testing.assert_allclose(centre, 0.1, atol=0.01)


def test_ctrl_c_once_the_run_is_over_keeps_its_status(tmp_path):
    """SIGINT after the last ``wrote`` line, during Python's shutdown and the compiler's clean-up
    after it: the run is done, so it exits 0, not killed by the signal."""
    import signal
    import time

    for delay in (0.0, 0.05, 0.2):
        child = subprocess.Popen([sys.executable, "-m", "warptex", "render", *SMALL, "--out", str(tmp_path / "out")], cwd=ROOT, stdout=subprocess.PIPE,
                                 stderr=subprocess.PIPE, text=True, preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
        assert child.stdout.readline().startswith("render: ")  # what it used, then what it wrote
        assert child.stdout.readline().startswith("wrote ")
        time.sleep(delay)
        child.send_signal(signal.SIGINT)
        out, err = child.communicate(timeout=60)
        assert child.returncode == 0, (delay, child.returncode, err[-2000:])


@pytest.mark.parametrize("command, delays", [
    (["render", "--resolution", "256x256", "--samples", "16"], (0.3, 0.6, 1.5, 4.0)),
    (["bake", "--size", "512", "--out", "{out}/asset.glb"], (0.4, 3.0)),
    (["fit", "--iters", "40", "--resolution", "64x96"], (0.4, 3.0)),
])
def test_ctrl_c_at_any_moment_is_one_line_exit_130_within_5_s(tmp_path, command, delays):
    """SIGINT to ``warptex`` while it starts (its imports: Python's own start-up, the first ~60 ms,
    comes before any of warptex's code), prepares or works: the one line, exit status 130 within
    5 s, and the folder's previous files as they were."""
    import signal
    import time

    out = tmp_path / "out"
    out.mkdir()
    before = {name: name.encode() * 100 for name in ("render.png", "asset.glb", "summary.json")}
    for name, data in before.items():
        (out / name).write_bytes(data)
    subprocess.run([sys.executable, "-m", "warptex", "--version"], cwd=ROOT, capture_output=True, check=True)  # byte-compiled
    # The delays count from the moment warptex's code runs: a signal in Python's own start-up (and
    # runpy's import of warptex.__main__) meets no code of ours, and on a loaded machine (a CI run)
    # that start-up alone takes longer than the first delay.
    start = time.perf_counter()
    subprocess.run([sys.executable, "-m", "warptex", "--version"], cwd=ROOT, capture_output=True, check=True)
    start_up = time.perf_counter() - start
    command = [c.replace("{out}", str(out)) for c in command]
    if "--out" not in command:
        command += ["--out", str(out)]
    for delay in delays:
        child = subprocess.Popen([sys.executable, "-m", "warptex", *command], cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                                 preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
        time.sleep(start_up + delay)
        sent = time.perf_counter()
        child.send_signal(signal.SIGINT)
        _, err = child.communicate(timeout=60)
        waited = time.perf_counter() - sent
        if child.returncode == 0:  # finished before the signal: nothing to check at this moment
            before = {p.name: p.read_bytes() for p in out.iterdir()}
            continue
        assert child.returncode == 130, (delay, child.returncode, err[-2000:])
        assert waited < 5.0, f"exit {waited:.1f} s after Ctrl-C ({delay} s in)"
        after = {p.name: p.read_bytes() for p in out.iterdir()}
        if err.strip() == "warptex: interrupted; its files were written before it":  # the signal came as they were renamed
            assert set(after) >= set(before) and after != before, delay
            before = after
        else:
            assert err.strip() == "warptex: interrupted; no files were written", (delay, err[-2000:])
            assert after == before, f"the previous files changed ({delay} s in)"


# Run in a child: each Warp module that a launch on the main thread loads (from the kernel cache or
# by compiling it) is printed. A command preloads its kernels first, on another thread, so that a
# cold start compiles them side by side and hears a Ctrl-C; any module named here was left out.
MAIN_THREAD_LOADS = """
import sys, threading
try:
    import warp._src.context as context
except ImportError:  # Warp before 1.10
    import warp.context as context
load = context.Module.load
def watched(self, device, *args, **kwargs):
    if not hasattr(self, "execs"):
        sys.exit("this Warp's modules keep no execs table")
    before = len(self.execs)
    loaded = load(self, device, *args, **kwargs)
    if threading.current_thread() is threading.main_thread() and len(self.execs) > before:
        print("main-thread load:", self.name, file=sys.stderr)
    return loaded
context.Module.load = watched
from warptex.apps.cli import entry
sys.argv = ["warptex", *sys.argv[1:]]
entry()
"""


@pytest.mark.parametrize("command", [
    ["render", "--resolution", "24x32", "--samples", "4"],
    ["render", "--mesh", "{mesh}", "--technique", "biplanar", "--resolution", "24x32"],
    ["bake", "--size", "64", "--out", "{out}/asset.glb"],
    ["fit", "--iters", "2", "--resolution", "24x32"],
])
def test_a_command_loads_no_kernel_module_on_its_main_thread(tmp_path, command):
    """``warptex fit`` rasterised its views and built its layers' mips before it preloaded its
    kernels: on a cold start the rasteriser compiled on the main thread for seconds, deaf to
    Ctrl-C (a CI run's "exit 5.0 s after Ctrl-C"). Every command's kernels are now preloaded before
    anything launches."""
    mesh = tmp_path / "box.obj"
    trimesh.creation.box().export(mesh)
    out = tmp_path / "out"
    command = [c.replace("{out}", str(out)).replace("{mesh}", str(mesh)) for c in command]
    if "--out" not in command:
        command += ["--out", str(out)]
    done = subprocess.run([sys.executable, "-c", MAIN_THREAD_LOADS, *command], cwd=ROOT, capture_output=True, text=True, timeout=600)
    if "keep no execs table" in done.stderr:
        pytest.skip("this Warp's modules keep no execs table: which thread loads them cannot be seen")
    assert done.returncode == 0, done.stderr[-2000:]
    assert "main-thread load" not in done.stderr, done.stderr[-2000:]


def test_a_command_compiles_the_modules_the_test_session_cached(tmp_path):
    """A Warp module's hash covers every kernel in it. The resolve kernels lived in the
    rasteriser's module but in a file of their own, which ``warptex fit`` never imported: its
    rasteriser hashed differently from ``warptex render``'s and from ``warptex.precompile()``'s,
    and compiled again on its first run. Each command's modules now hash as they do with every
    kernel made (this session's :func:`warptex.precompile`)."""
    from warptex.kernels import all_kernels

    code = """
import importlib, json, sys
app = importlib.import_module("warptex.apps." + sys.argv[1])  # that command's module alone, as its process imports
kernels = {"fit_demo": lambda: app._kernels(4, True, "cpu"), "render": lambda: app._kernels(True, "cpu") + app._kernels(False, "cpu"),
           "bake": lambda: app._kernels("triplanar", None, False, 4, "cpu")}[sys.argv[1]]()
print(json.dumps({"package": __import__("warptex").__file__, "hashes": {k.module.name: k.module.hash_module().hex() for k in kernels}}))
"""
    mine = {k.module.name: k.module for k in all_kernels((4, 8))}
    if not hasattr(next(iter(mine.values())), "hash_module"):
        pytest.skip("this Warp's modules have no hash_module()")
    # The copy of warptex this process runs: CI installs one (pip install .) beside the checkout,
    # and the two copies' modules hash otherwise (their headers' paths are in the build options).
    env = {**os.environ, "PYTHONPATH": str(Path(wt.__file__).parents[1])}
    for command in ("fit_demo", "render", "bake"):
        done = subprocess.run([sys.executable, "-c", code, command], cwd=tmp_path, env=env, capture_output=True, text=True, timeout=300)
        assert done.returncode == 0, done.stderr[-2000:]
        child = json.loads(done.stdout.strip().splitlines()[-1])
        assert child["package"] == wt.__file__, "the child imported another copy of warptex"
        theirs = child["hashes"]
        differ = [name for name, digest in theirs.items() if name in mine and mine[name].hash_module().hex() != digest]
        assert not differ, f"{command}: modules that hash otherwise than with every kernel made: {differ}"


def test_ctrl_c_while_a_cold_fit_compiles_exits_within_5_s(tmp_path):
    """On an empty Warp kernel cache, ``warptex fit`` compiles its splat kernels for seconds; a
    Ctrl-C once that has begun still ends it within 5 s, with its one line and status 130 (the
    kernels compile in the background, ``warptex._compile.preload``, not in the main thread at
    their first launch, which heard nothing until the compile was done)."""
    import signal
    import time

    cache = tmp_path / "cache"
    env = {**os.environ, "WARP_CACHE_PATH": str(cache)}
    child = subprocess.Popen([sys.executable, "-m", "warptex", "fit", "--iters", "40", "--resolution", "64x96", "--out", str(tmp_path / "out")], cwd=ROOT,
                             stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env, preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    deadline = time.perf_counter() + 120
    while not any("splat" in p.name and "grad" in p.name for p in cache.glob("*/*")) and child.poll() is None and time.perf_counter() < deadline:
        time.sleep(0.02)  # until the build of the splat's gradient module (the longest) begins
    assert child.poll() is None, "the fit ended before its splat kernels compiled"
    time.sleep(0.2)
    sent = time.perf_counter()
    child.send_signal(signal.SIGINT)
    _, err = child.communicate(timeout=120)
    waited = time.perf_counter() - sent
    assert child.returncode == 130, (child.returncode, err[-2000:])
    assert waited < 5.0, f"exit {waited:.1f} s after Ctrl-C"
    assert err.strip() == "warptex: interrupted; no files were written", err[-2000:]


def _without_torch(code: str, env: dict | None = None) -> subprocess.CompletedProcess:
    """Run ``code`` in a Python where ``import torch`` fails, as on a machine without PyTorch."""
    return subprocess.run([sys.executable, "-c", "import sys; sys.modules['torch'] = None\n" + code], cwd=ROOT, capture_output=True, text=True,
                          env={**os.environ, **(env or {})}, timeout=300)


def test_without_pytorch_the_bridge_and_a_torchrun_fit_say_how_to_install_it(tmp_path):
    """Issue 50 item 9: ``import warptex.torch`` said only "No module named 'torch'", and a fit
    started by torchrun printed its "needs PyTorch" line, then a traceback (``Job.close`` imported
    torch again). Both now say it in one line, with an install command that works (the package
    index has no warptex, so not ``pip install 'warptex[torch]'``)."""
    hint = "pip install torch (without a GPU, the CPU build: pip install torch --index-url https://download.pytorch.org/whl/cpu)"
    done = _without_torch("import warptex.torch")
    assert done.returncode == 1 and f"ImportError: warptex.torch needs PyTorch, which is not installed: {hint}" in done.stderr, done.stderr
    env = {"WORLD_SIZE": "2", "RANK": "0", "LOCAL_RANK": "0", "LOCAL_WORLD_SIZE": "2", "MASTER_ADDR": "127.0.0.1", "MASTER_PORT": "29999"}
    done = _without_torch(f"from warptex.apps.cli import entry; sys.argv = ['warptex', 'fit', '--iters', '1', '--out', {str(tmp_path / 'out')!r}]; entry()", env)
    assert done.returncode == 1, done.stderr
    assert done.stderr.strip().splitlines()[-1] == f"warptex: error: fit: torchrun started 2 processes (WORLD_SIZE=2), which needs PyTorch, not installed: {hint}", done.stderr
    assert "Traceback" not in done.stderr and not (tmp_path / "out").exists()


def test_a_mistyped_command_is_named_with_the_one_it_resembles(capsys):
    """``warptex rendr`` said "unrecognized arguments: rendr" (issue 50 item 14): no command takes
    a positional argument, so a first word that is not a command is a mistyped one."""
    for word, said in (("rendr", "unknown command 'rendr'; did you mean 'render'?"), ("bkae", "unknown command 'bkae'; did you mean 'bake'?"), ("xyz", "unknown command 'xyz'")):
        with pytest.raises(SystemExit) as exit_:
            main([word, "--out", "unused"])
        assert exit_.value.code == 2
        assert capsys.readouterr().err.splitlines()[-1] == f"warptex: error: {said} (commands: render, demo, fit, bake, assets)"


def test_a_texture_that_is_not_one_is_refused_naming_its_file(tmp_path, capsys):
    """A G-buffer EXR passed as ``--texture`` holds infinite depth where nothing was drawn: the
    error said "Texture(): image contains non-finite texels" without the file (issue 50 item 14)."""
    assert main(["render", "--resolution", "24x32", "--out", str(tmp_path / "g")]) == 0
    gbuffer = tmp_path / "g" / "gbuffer.exr"
    for command in (["render", "--mesh", str(_obj(tmp_path / "tri.obj", "v -1 -1 0\nv 1 -1 0\nv 0 1 0\nf 1 2 3\n")), "--texture", str(gbuffer), *SMALL],
                    ["bake", "--texture", str(gbuffer), "--size", "64"]):
        assert main([*command, "--out", str(tmp_path / "out" / "x.glb" if command[0] == "bake" else tmp_path / "out")]) == 1
        err = capsys.readouterr().err.strip()
        assert err.startswith(f"warptex: error: Texture.from_file(): {str(gbuffer)!r}: image contains non-finite texels"), err
    assert not (tmp_path / "out").exists()


def test_bake_help_gives_the_padding_the_code_uses(capsys):
    """``bake --help`` said --padding defaults to twice the gutter; bake() uses the gutter (issue 50 item 11)."""
    import warptex as wt

    with pytest.raises(SystemExit):
        main(["bake", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert "texels between the atlas's charts (default: the gutter)" in text
    assert "default ``gutter``" in wt.bake.__doc__  # the library says the same


def test_quiet_turns_the_progress_bar_off(monkeypatch, tmp_path):
    """render, bake and fit show a progress bar on a terminal (tqdm's choice when ``progress`` is
    None); ``--quiet`` turns it off (issue 50 item 7)."""
    from warptex.apps import bake, fit_demo, render

    seen = {}

    def spy(name):
        def run(out, **kwargs):
            seen[name] = kwargs["progress"]
            return []
        return run

    monkeypatch.setattr(render, "run_render", spy("render"))
    monkeypatch.setattr(bake, "run_bake", spy("bake"))
    monkeypatch.setattr(fit_demo, "run_fit", lambda out, **kwargs: (seen.__setitem__("fit", kwargs["progress"]), {"files": []})[1])
    for quiet in ([], ["--quiet"], ["-q"]):
        for command in ("render", "bake", "fit"):
            assert main([command, "--out", str(tmp_path / "x.glb"), *quiet]) == 0
        assert seen == dict.fromkeys(("render", "bake", "fit"), False if quiet else None)


def test_ctrl_c_while_tqdm_makes_its_lock_is_the_one_line(tmp_path):
    """tqdm makes its write lock on first use, importing multiprocessing with its thread lock held.
    A Ctrl-C there, in the line saying what a bake uses (``tqdm.write``), left tqdm without a lock
    and the run ended with tqdm's AttributeError (exit 1) instead of the one line and 130. The lock
    is now made while start-up defers Ctrl-C. Here making it is slowed down, and the signal sent
    while it is made."""
    import signal

    mesh = _obj(tmp_path / "tri.obj", "v -1 -1 0\nv 1 -1 0\nv 0 1 0\nf 1 2 3\n")
    child_code = (
        "import sys, time\n"
        "import tqdm.std as std\n"
        "made = std.TqdmDefaultWriteLock.create_mp_lock.__func__\n"
        "def slow(cls):\n"
        "    sys.stderr.write('making the lock\\n'); sys.stderr.flush(); time.sleep(2.0); made(cls)\n"
        "std.TqdmDefaultWriteLock.create_mp_lock = classmethod(slow)\n"
        "from warptex.apps.cli import entry\n"
        f"sys.argv = ['warptex', 'bake', '--mesh', {str(mesh)!r}, '--size', '32', '--out', {str(tmp_path / 'o' / 'a.glb')!r}]\n"
        "entry()\n"
    )
    child = subprocess.Popen([sys.executable, "-c", child_code], cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                             preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    assert child.stderr.readline().strip() == "making the lock"
    child.send_signal(signal.SIGINT)
    _, err = child.communicate(timeout=120)
    assert child.returncode == 130, err[-2000:]
    assert err.strip().splitlines()[-1] == "warptex: interrupted; no files were written", err[-2000:]
    assert not (tmp_path / "o").exists()
