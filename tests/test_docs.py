"""Every code block of README.md and of the docs (``docs/*.md``) runs, so they cannot rot.

The pages are parsed here, the README first, then the docs pages by name (a block's name is its
section's heading, unique across the pages): each ```python block is executed (in a fresh namespace, or after the
blocks it continues, see ``CONTINUES``), and each ``warptex ...`` (or ``python examples/...``)
command of a ```sh block is run through the CLI's ``main(argv)`` (``torchrun ... -m warptex`` in
its own processes), with small-size options
swapped in so the whole module stays fast. Install steps (``python3 -m venv``, ``pip install``,
``git clone``), the test run itself (``pytest``) and the docs build (``sphinx-build``, which CI
runs) are the only commands not run. Every block and command runs in its own copy of a folder made
only by the docs' own commands (``out/`` is
``warptex render --out out`` at a small size, ``assets/`` is ``warptex assets --out assets``),
with ``../shared`` beside it as beside the repository: a snippet that reads a file nobody has
fails here (issue 34 found ``rock.png``, ``snow.png`` and ``splat.png`` named but made nowhere);
blocks that read ``../shared`` skip when it is absent. ``EXPECTED_BLOCKS`` and ``EXPECTED_COMMANDS`` fail when a block or command is added, so it
cannot slip through untested.
"""

from __future__ import annotations

import json
import os
import runpy
import shlex
import shutil
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest
import warp as wp

import warptex as wt
from warptex.apps.assets import ASSET_NAMES
from warptex.apps.cli import main as cli_main

REPO = Path(__file__).resolve().parents[1]
README = REPO / "README.md"
PAGES = [README, *sorted((REPO / "docs").glob("*.md"))]
SHARED = REPO.parent / "shared"

# Fenced blocks per info string: a new block must be added here, and so gets a test.
EXPECTED_BLOCKS = {"python": 17, "sh": 10, "": 1, "text": 1}
EXPECTED_COMMANDS = {"warptex": 17, "python": 2, "skipped": 15, "torchrun": 1}

# Python blocks that continue earlier ones (by "<section> #<n>"): they run after those, in one namespace.
CONTINUES = {
    "Triplanar, biplanar and triplanar normal mapping #2": ["Triplanar, biplanar and triplanar normal mapping #1"],
    "Stochastic tiling #2": ["Splat-map layers (terrain) #1", "Stochastic tiling #1"],
}
# Text swapped in Python blocks to keep them fast: (block, old, new).
PYTHON_QUICK = [
    ("Fitting splat maps and tiling to images #2", "iters=240", "iters=3"),
    ("Baking into a UV texture, exported as glTF #1", "size=2048", "size=256"),
    ("Baking into a UV texture, exported as glTF #3", "1024", "512"),
    ("Pictures larger than memory: tiles #1", "1024, 1024", "96, 128"),
    ("Pictures larger than memory: tiles #1", "64 << 20", "1 << 20"),  # bands of 8 rows
    ("Using it #3", '"cuda:0"', '"cpu"'),  # a CUDA graph's capture, on the CPU here (tests/test_cuda.py runs CUDA's)
]

QUICK_RESOLUTION = "48x64"  # of `warptex render` and `warptex demo`, and of the out/ the Python blocks read


@dataclass
class Block:
    page: str  # its file, relative to the repository
    section: str
    number: int  # 1, 2... within its section
    lang: str
    line: int  # of the opening fence, 1-based
    text: str

    @property
    def name(self) -> str:
        return f"{self.section} #{self.number}"

    @property
    def first_line(self) -> str:
        return next((ln.strip() for ln in self.text.splitlines() if ln.strip()), "")


def page_blocks() -> list[Block]:
    """The fenced blocks of every page; Sphinx directives (```{toctree}, ```{eval-rst}) are not code."""
    blocks, counts = [], {}
    for page in PAGES:
        name, section, open_block = str(page.relative_to(REPO)), f"(top of {page.name})", None
        for i, line in enumerate(page.read_text(encoding="utf-8").splitlines(), start=1):
            if open_block is not None:
                if line.strip() == "```":
                    if not open_block[0].startswith("{"):
                        blocks.append(Block(name, section, counts[section], open_block[0], open_block[1], "\n".join(open_block[2])))
                    open_block = None
                else:
                    open_block[2].append(line)
            elif line.startswith("```"):
                counts[section] = counts.get(section, 0) + 1
                open_block = (line[3:].strip().lower(), i, [])
            elif line.startswith("#"):
                section = line.lstrip("#").strip()
        assert open_block is None, f"{name}: the block opened at line {open_block[1]} is never closed"
    return blocks


@dataclass
class Command:
    block: Block
    line: int
    argv: list[str]
    kind: str  # "warptex", "torchrun" (``torchrun ... -m warptex``), "python" (a script of the repository) or "skipped"

    @property
    def id(self) -> str:
        return f"L{self.line} {shlex.join(self.argv)[:70]}"


_INSTALL = (["python3", "-m", "venv"], ["python", "-m", "venv"], ["git", "clone"])


def _command_kind(argv: list[str]) -> str:
    exe = Path(argv[0]).name
    if exe == "warptex" or argv[:3] in (["python", "-m", "warptex"], ["python3", "-m", "warptex"]):
        return "warptex"
    if exe == "torchrun" and "-m" in argv and argv[argv.index("-m") + 1 :][:1] == ["warptex"]:
        return "torchrun"
    if any(argv[: len(p)] == p for p in _INSTALL) or exe in ("pip", "pip3", "pytest", "sphinx-build") or argv[1:3] == ["-m", "pip"]:
        return "skipped"  # install steps, and the test suite itself
    if exe in ("python", "python3") and len(argv) > 1 and argv[1].endswith(".py"):
        return "python"
    raise AssertionError(f"the docs: no rule to test the command {shlex.join(argv)!r}; add one to tests/test_docs.py")


def page_commands() -> list[Command]:
    commands = []
    for block in BLOCKS:
        if block.lang not in ("sh", "bash", "shell", "console"):
            continue
        for offset, line in enumerate(block.text.splitlines(), start=1):
            words = shlex.split(line, comments=True)
            if words and words[0] == "$":
                words = words[1:]
            while words:
                cut = words.index("&&") if "&&" in words else len(words)
                commands.append(Command(block, block.line + offset, words[:cut], _command_kind(words[:cut])))
                words = words[cut + 1 :]
    return commands


BLOCKS = page_blocks()
COMMANDS = page_commands()
PYTHON_BLOCKS = [b for b in BLOCKS if b.lang == "python"]


def test_every_block_and_command_is_accounted_for():
    found = {}
    for b in BLOCKS:
        found[b.lang] = found.get(b.lang, 0) + 1
    assert found == EXPECTED_BLOCKS, "the docs' code blocks changed: update EXPECTED_BLOCKS (and make sure the new ones run here)"
    kinds = {}
    for c in COMMANDS:
        kinds[c.kind] = kinds.get(c.kind, 0) + 1
    assert kinds == EXPECTED_COMMANDS, "the docs' shell commands changed: update EXPECTED_COMMANDS"
    names = {b.name for b in PYTHON_BLOCKS}
    assert len(names) == len(PYTHON_BLOCKS), "two pages' Python blocks share a section name: rename a heading"
    for name in [*CONTINUES, *(n for deps in CONTINUES.values() for n in deps), *(q[0] for q in PYTHON_QUICK)]:
        assert name in names, f"tests/test_docs.py names a block {name!r} that no longer exists"
    # Text blocks are the layout listing only.
    assert all(b.section == "Layout" for b in BLOCKS if b.lang == "")


# -- the files the README names ------------------------------------------------------------------


def _make_inputs(folder: Path) -> None:
    """What the README says to run before its snippets: the quick start's render (small) and
    ``warptex assets``; ``../shared`` is linked beside the folder, as it lies beside the repository."""
    repo = folder / "repo"
    repo.mkdir()
    assert cli_main(["render", "--out", str(repo / "out"), "--resolution", QUICK_RESOLUTION]) == 0
    assert cli_main(["assets", "--out", str(repo / "assets")]) == 0
    if SHARED.is_dir():
        (folder / "shared").symlink_to(SHARED, target_is_directory=True)


@pytest.fixture(scope="module")
def inputs(tmp_path_factory) -> Path:
    folder = tmp_path_factory.mktemp("readme_inputs")
    _make_inputs(folder)
    return folder


@pytest.fixture
def workdir(inputs, tmp_path, monkeypatch) -> Path:
    """A fresh copy of the inputs (``repo/``, ``../shared`` beside it), ``repo/`` the current directory."""
    shutil.copytree(inputs, tmp_path, dirs_exist_ok=True, symlinks=True)
    monkeypatch.chdir(tmp_path / "repo")
    return tmp_path / "repo"


# -- Python blocks -------------------------------------------------------------------------------


def _source(block: Block) -> str:
    text = block.text
    for name, old, new in PYTHON_QUICK:
        if name == block.name:
            assert old in text, f"{block.name}: {old!r} is gone; update PYTHON_QUICK"
            text = text.replace(old, new)
    return text


def _run_python(block: Block, namespace: dict) -> None:
    exec(compile(_source(block), f"{block.page}:{block.line} ({block.name})", "exec"), namespace)  # noqa: S102 (the docs are ours)


def _shape(x):
    return tuple(x.shape)


def _check_first_look(ns, d):
    assert _shape(ns["colour"]) == (256, 256, 1)
    image = wt.io.read_image(d / "out" / "bunny_brick.png")
    assert image.shape == (256, 256, 1) and image.std() > 0.05  # the bunny in bricks, on black


def _check_using_it(ns, d):
    assert _shape(ns["colour"]) == (1000, 1)  # brick.png is grey: C = 1
    assert wt.io.read_image(d / "out" / "sampled.png").shape == (64, 64, 1)  # the snippet saves its picture
    assert ns["tex"].grad().shape == (64, 64, 3) and np.abs(ns["tex"].grad()).sum() > 0
    assert ns["uv"].grad.numpy().shape == (1000, 2) and np.isfinite(ns["uv"].grad.numpy()).all()


def _check_graph_capture(ns, d):
    replayed = ns["out"].numpy().copy()  # the replay's lookup of the new UVs, not the captured call's
    assert np.abs(replayed - wt.sample(ns["tex"], ns["uv"].numpy()).numpy()).max() == 0.0
    ns["uv"].assign(np.zeros((4096, 2), np.float32))
    wp.capture_launch(ns["capture"].graph)
    np.testing.assert_array_equal(ns["out"].numpy(), wt.sample(ns["tex"], np.zeros((4096, 2), np.float32)).numpy())
    assert not np.array_equal(ns["out"].numpy(), replayed)


def _check_gbuffers(ns, d):
    g = wt.load_gbuffer(d / "out" / "g.exr")  # under out/ (ignored by git), not the repository root
    assert g.resolution == (512, 512) and g.mask.numpy().sum() > 1000  # the bunny fills the view
    assert ns["g"].resolution == (512, 512) and ns["g"].uv_sets == {}


def _check_supersampled(ns, d):
    assert ns["g"].samples == 16 and ns["g"].resolution == (512, 512) and _shape(ns["colour"]) == (512, 512, 1)
    alpha = ns["alpha"].numpy()
    assert alpha.shape == (128, 128) and ((alpha > 0) & (alpha < 1)).sum() > 50  # the silhouette's pixels
    assert _shape(ns["premultiplied"]) == (128, 128, 1)


def _check_tiles(ns, d):
    """The image made in bands is the whole image, bit for bit."""
    import warptex as wt

    whole = wt.resolve(wt.triplanar(wt.rasterize("../shared/data/meshes/bunny.ply", ns["camera"], samples=4), ns["brick"], tiling=20.0), 4).numpy()
    assert ns["image"].shape == whole.shape == (96, 128, 1) and ns["image"].tobytes() == whole.tobytes()
    assert ns["tile"].count == 12 and ns["tile"].rows == slice(88, 96)


def _check_triplanar(ns, d):
    assert _shape(ns["colour"]) == (512, 512, 1) and _shape(ns["normals"]) == (512, 512, 3)
    assert ns["image"].shape == (512, 512, 3) and np.isfinite(ns["image"]).all()
    n = ns["normals"].numpy()[ns["g"].mask.numpy() > 0]
    np.testing.assert_allclose(np.linalg.norm(n, axis=-1), 1.0, atol=1e-4)


def _check_tiling_gradient(ns, d):
    grad = ns["tiling"].grad.numpy()
    assert grad.shape == (1,) and np.isfinite(grad).all() and grad[0] != 0


def _check_six_planar(ns, d):
    g = ns["g"]
    assert _shape(ns["colour"]) == (128, 128, 4) and _shape(ns["terrain"]) == (128, 128, 4)
    n, mask = g.normal.numpy(), g.mask.numpy() > 0
    top, bottom = mask & (n[..., 1] > 0.93), mask & (n[..., 1] < -0.93)  # other weights below (0.4)^8
    assert top.sum() > 30 and bottom.sum() > 30, (top.sum(), bottom.sum())
    colour, terrain = ns["colour"].numpy(), ns["terrain"].numpy()
    for name, region, face in (("top", top, ns["grass"]), ("bottom", bottom, ns["rock"])):
        alone = wt.triplanar(g, face, sharpness=8.0).numpy()
        np.testing.assert_allclose(colour[region], alone[region], atol=2e-3, err_msg=f"{name}: that face's texture")
    plain = wt.splat(g, ns["layers"], ns["maps"], projection="triplanar", sharpness=8.0).numpy()
    np.testing.assert_allclose(terrain[top], plain[top], atol=2e-3)  # grass reads itself on top
    assert np.abs(terrain[bottom] - plain[bottom]).max() > 0.05  # and rock beneath


def _check_torch(ns, d):
    assert _shape(ns["colour"]) == (128, 128, 3) and ns["loss"].item() > 0
    assert ns["texture"].grad.abs().sum() > 0 and ns["tiling"].grad.shape == () and ns["tiling"].grad != 0


def _check_splat(ns, d):
    assert _shape(ns["colour"]) == (48, 64, 4)
    assert ns["layers"].num_layers == 4 and ns["layers"].channels == 4


def _check_stochastic(ns, d):
    assert _shape(ns["out"]) == (1000, 1) and np.isfinite(ns["out"].numpy()).all()


def _check_stochastic_inside(ns, d):
    assert _shape(ns["out"]) == (48, 64, 1)


def _check_bake(ns, d):
    assert _shape(ns["baked"].color) == (256, 256, 1) and _shape(ns["baked"].normal) == (256, 256, 3)
    assert ns["baked"].layout.source == "xatlas"
    for name in ("bunny.glb", "bunny_color.png", "bunny_normal.png"):
        assert (d / "out" / name).is_file(), name


def _check_bake_torch(ns, d):
    assert tuple(ns["baked"].shape) == (512, 512, 3) and ns["g"].resolution == (512, 512)
    assert ns["texture"].grad.abs().sum() > 0 and ns["tiling"].grad != 0


def _check_formats(ns, d):
    assert ns["stored"].format.value == "srgb8" and ns["stored"].nbytes <= 0.26 * wt.Texture(ns["master"], mipmaps=False).nbytes
    assert ns["error"] < 0.1  # from 0.33: the stored 8-bit texture came close to the photo


def _check_fit(ns, d):
    assert np.isfinite(ns["result"].final_psnr) and len(ns["result"].history["psnr"]) >= 3
    assert ns["params"].weights().shape == (129, 129, 4)


CHECKS = {
    "A first look #1": _check_first_look,
    "Using it #2": _check_using_it,
    "Using it #3": _check_graph_capture,
    "Texel formats #1": _check_formats,
    "PyTorch #1": _check_torch,
    "G-buffers #1": _check_gbuffers,
    "G-buffers #2": _check_supersampled,
    "Pictures larger than memory: tiles #1": _check_tiles,
    "Triplanar, biplanar and triplanar normal mapping #1": _check_triplanar,
    "Triplanar, biplanar and triplanar normal mapping #2": _check_tiling_gradient,
    "A texture per face (six-planar) #1": _check_six_planar,
    "Splat-map layers (terrain) #1": _check_splat,
    "Stochastic tiling #1": _check_stochastic,
    "Stochastic tiling #2": _check_stochastic_inside,
    "Fitting splat maps and tiling to images #2": _check_fit,
    "Baking into a UV texture, exported as glTF #1": _check_bake,
    "Baking into a UV texture, exported as glTF #3": _check_bake_torch,
}


@pytest.mark.parametrize("block", PYTHON_BLOCKS, ids=[f"L{b.line} {b.name}" for b in PYTHON_BLOCKS])
def test_python_block(block, workdir):
    by_name = {b.name: b for b in PYTHON_BLOCKS}
    runs = [by_name[before] for before in CONTINUES.get(block.name, [])] + [block]  # a block continues the ones before it
    if any("../shared/" in b.text for b in runs) and not SHARED.is_dir():
        pytest.skip(f"{SHARED} not found: this block (or one it continues) reads the shared data")
    if any("import torch" in b.text for b in runs):
        pytest.importorskip("torch", reason="PyTorch is not installed (pip install torch)")
    if any("wp.ScopedCapture" in b.text for b in runs) and tuple(map(int, wp.config.version.split(".")[:2])) < (1, 19):
        pytest.skip("the block captures a graph, on the CPU here: CPU graph capture came with Warp 1.19")
    namespace = {"__name__": "__readme__"}
    for before in CONTINUES.get(block.name, []):
        _run_python(by_name[before], namespace)
    _run_python(block, namespace)
    assert block.name in CHECKS, f"add a check of what the block {block.name!r} of {block.page} promises to CHECKS"
    CHECKS[block.name](namespace, workdir)


# -- shell commands --------------------------------------------------------------------------------


def _set_option(argv: list[str], option: str, value: str) -> list[str]:
    """``argv`` with ``option value`` replacing any given value (``--opt v`` or ``--opt=v``), else appended."""
    out, i = [], 0
    while i < len(argv):
        if argv[i] == option:
            i += 2
            continue
        if argv[i].startswith(option + "="):
            i += 1
            continue
        out.append(argv[i])
        i += 1
    return out + [option, value]


def _option(argv: list[str], option: str, default=None):
    for i, word in enumerate(argv):
        if word == option and i + 1 < len(argv):
            return argv[i + 1]
        if word.startswith(option + "="):
            return word.split("=", 1)[1]
    return default


def _shared_paths(argv: list[str]) -> list[str]:
    """``../shared/...`` (beside the repository) as an absolute path; skip when it is absent."""
    out = []
    for word in argv:
        if word.startswith("../shared/"):
            path = SHARED / word[len("../shared/") :]
            if not path.exists():
                pytest.skip(f"{path} not found: this command of the docs needs the shared data folder")
            word = str(path)
        out.append(word)
    return out


def _quick(argv: list[str]) -> list[str]:
    """The README's ``warptex`` arguments with small sizes and few iterations."""
    argv = _shared_paths(argv)
    command = argv[0] if argv and argv[0] in COMMAND_NAMES else "render"
    if command == "assets":
        return argv
    if _option(argv, "--device", "cpu").startswith("cuda") and wp.get_cuda_device_count() == 0:
        argv = _set_option(argv, "--device", "cpu")  # the command's other options still run
    if command == "bake":
        argv = _set_option(argv, "--size", "256")
    elif command in ("render", "demo"):
        argv = _set_option(argv, "--resolution", QUICK_RESOLUTION)
    else:
        argv = _set_option(argv, "--iters", "3")
        argv = _set_option(argv, "--report-every", "1")
        if "--target" not in argv:
            argv = _set_option(argv, "--resolution", "24x32")
        if "--map-size" in argv:
            argv = _set_option(argv, "--map-size", "16x16")
    return argv


COMMAND_NAMES = ("render", "demo", "fit", "bake", "assets")
RENDER_FILES = ("render.png", "albedo.png", "normals.png", "render.exr", "gbuffer.exr")
DEMO_FILES = ("demo.png", "demo_trilinear.exr")
FIT_FILES = ("target.png", "initial.png", "fitted.png", "comparison.png", "splat_fitted.png", "splat_maps.png",
             "splat_fitted.exr", "curve.png", "summary.json")  # as the README lists them
FIT_SYNTHETIC_FILES = ("splat_true.png",)


def _check_outputs(argv: list[str], folder: Path, printed: str) -> None:
    command = argv[0] if argv[0] in COMMAND_NAMES else "render"
    out = folder / _option(argv, "--out", {"fit": "out/fit", "bake": "out/asset.glb", "assets": "assets"}.get(command, "out"))
    wrote = {Path(line[len("wrote ") :]).name for line in printed.splitlines() if line.startswith("wrote ")}
    if command == "bake":
        for name in (out.name, f"{out.stem}_color.png"):
            assert (out.parent / name).is_file() and name in wrote, f"the docs promise {name} from warptex {shlex.join(argv)}"
        assert wt.io.read_image(out.parent / f"{out.stem}_color.png").shape == (256, 256, 3)
    elif command == "assets":
        for name in ASSET_NAMES:
            assert (out / name).is_file() and name in wrote, f"the docs promise {name} from warptex {shlex.join(argv)}"
        assert wt.io.read_image(out / "grass.png").shape == (256, 256, 4)  # colour + height in alpha
    elif command == "render":
        for name in RENDER_FILES:
            assert (out / name).is_file() and name in wrote, f"the docs promise {name} from warptex {shlex.join(argv)}"
        h, w = (int(v) for v in QUICK_RESOLUTION.split("x"))
        assert wt.io.read_image(out / "render.png").shape == (h, w, 3)
        assert wt.load_gbuffer(out / "gbuffer.exr").resolution == (h, w)
    elif command == "demo":
        for name in DEMO_FILES:
            assert (out / name).is_file() and name in wrote, f"the docs promise {name} from warptex {shlex.join(argv)}"
    else:
        synthetic = "--target" not in argv
        for name in FIT_FILES + (FIT_SYNTHETIC_FILES if synthetic else ()):
            assert (out / name).is_file() and name in wrote, f"the docs promise {name} from warptex {shlex.join(argv)}"
        summary = json.loads((out / "summary.json").read_text())
        assert summary["iterations"] == 3 and summary["mode"] == ("synthetic" if synthetic else "user")
        assert "fit: 3 iterations" in printed
        map_size = tuple(int(v) for v in _option(argv, "--map-size", "129x129").split("x"))
        assert wt.io.read_image(out / "splat_fitted.exr").shape == (*map_size, 4)


WARPTEX_COMMANDS = [c for c in COMMANDS if c.kind == "warptex"]


@pytest.mark.parametrize("command", WARPTEX_COMMANDS, ids=[c.id for c in WARPTEX_COMMANDS])
def test_warptex_command(command, workdir, capsys):
    argv = command.argv[1:] if Path(command.argv[0]).name == "warptex" else command.argv[3:]
    argv = _quick(argv)
    rc = cli_main(argv)
    captured = capsys.readouterr()
    assert rc == 0, f"`warptex {shlex.join(argv)}` exited {rc}:\n{captured.err}"
    _check_outputs(argv, workdir, captured.out)


TORCHRUN_COMMANDS = [c for c in COMMANDS if c.kind == "torchrun"]


@pytest.mark.parametrize("command", TORCHRUN_COMMANDS, ids=[c.id for c in TORCHRUN_COMMANDS])
def test_torchrun_command(command, workdir):
    pytest.importorskip("torch.distributed", reason="PyTorch is not installed (pip install torch): torchrun comes with it")
    cut = command.argv.index("-m")
    launcher, argv = command.argv[1:cut], _quick(command.argv[cut + 2 :])
    env = {**os.environ, "WARPTEX_NUM_THREADS": "1", "OMP_NUM_THREADS": "1", "PYTHONPATH": str(REPO)}
    done = subprocess.run([sys.executable, "-m", "torch.distributed.run", *launcher, "-m", "warptex", *argv], cwd=workdir, env=env, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, f"`torchrun {shlex.join(command.argv[1:])}` exited {done.returncode}:\n{done.stderr[-3000:]}"
    _check_outputs(argv, workdir, done.stdout)


SCRIPT_COMMANDS = [c for c in COMMANDS if c.kind == "python"]
# Small-run arguments of the repository's scripts: script -> {option: value}.
SCRIPT_QUICK = {"examples/fit_splat.py": {"--iters": "2"}, "examples/torch_fit.py": {"--iters": "2"}}
SCRIPT_FILES = {"examples/fit_splat.py": ("out/fit_example/target.png", "out/fit_example/fitted.png"), "examples/torch_fit.py": ("out/torch_fit/target.png", "out/torch_fit/fitted.png")}


@pytest.mark.parametrize("command", SCRIPT_COMMANDS, ids=[c.id for c in SCRIPT_COMMANDS])
def test_script_command(command, workdir, monkeypatch, capsys):
    script, argv = command.argv[1], command.argv[2:]
    if script == "examples/torch_fit.py":
        pytest.importorskip("torch", reason="PyTorch is not installed (pip install torch)")
    assert script in SCRIPT_QUICK, f"add {script}'s small-run options to SCRIPT_QUICK"
    for option, value in SCRIPT_QUICK[script].items():
        argv = _set_option(argv, option, value)
    monkeypatch.setattr(sys, "argv", [str(REPO / script), *argv])
    with pytest.raises(SystemExit) as exit_:
        runpy.run_path(str(REPO / script), run_name="__main__")
    assert exit_.value.code in (0, None), capsys.readouterr().err
    for name in SCRIPT_FILES.get(script, ()):
        assert (workdir / name).is_file()
