"""The CPU lanes' native code (``warptex.kernels.native``): headers that resolve their twins, compile
alone, are formatted, and name their own file and line in a compile error; and stubs that call
only what the headers define."""

import importlib
import inspect
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
import warp as wp

from warptex.kernels import native
from warptex.kernels.texels import read_channels

FUNCTION = type(read_channels)  # Warp's @wp.func type (its module path differs across releases)
HEADERS = sorted(native.folder().glob("*.h"))
TWIN = re.compile(r"//\s*twin:\s*(\S+)")
DEFINED = re.compile(r"\b(wt_\w+)\s*(?:<[^<>()]*>)?\s*\(")  # a call, its template arguments given or not


def _twins(text: str) -> list[str]:
    return TWIN.findall(text)


def twin_errors(header: Path) -> list[str]:
    """What is wrong with the ``// twin: module.function`` references of ``header`` (a function of
    ``warptex.kernels.<module>``; ``module.factory:name``, a function ``name`` that ``factory``
    makes): each must name a ``@wp.func`` (or a factory that defines the named function)."""
    errors = []
    for ref in _twins(header.read_text()):
        path, _, inner = ref.partition(":")
        module_name, _, attr = path.rpartition(".")
        try:
            module = importlib.import_module(f"warptex.kernels.{module_name}")
        except ImportError:
            errors.append(f"{header.name}: twin {ref}: no module warptex.kernels.{module_name}")
            continue
        target = getattr(module, attr, None)
        if inner:
            source = inspect.getsource(target) if callable(target) else ""
            if not re.search(rf"\bdef {re.escape(inner)}\(", source):
                errors.append(f"{header.name}: twin {ref}: {module_name}.{attr} defines no function {inner}")
        elif not isinstance(target, FUNCTION):
            errors.append(f"{header.name}: twin {ref}: {module_name}.{attr} is not a @wp.func")
    return errors


def test_the_package_ships_every_header():
    assert [h.name for h in HEADERS] == sorted(native.HEADERS)


@pytest.mark.parametrize("header", HEADERS, ids=lambda h: h.name)
def test_every_twin_reference_names_a_warp_function(header):
    """Each header names the scalar blocks its functions restate; a renamed or deleted twin fails
    here, by header and reference."""
    assert not twin_errors(header)


def test_a_broken_twin_reference_is_caught(tmp_path):
    """The check itself fails on a reference to nothing (here a typo of a real one)."""
    broken = tmp_path / "wt_broken.h"
    broken.write_text("// twin: texels.reduce_cord\n// twin: splat_blend.blend_functions:blends\n// twin: nosuch.thing\n")
    errors = twin_errors(broken)
    assert len(errors) == 3 and "reduce_cord" in errors[0] and "blends" in errors[1] and "nosuch" in errors[2]


def _stubs():
    """Every native function of ``warptex.kernels``: its name and the C++ of its CPU body."""
    from warptex.kernels import all_kernels

    all_kernels()
    seen = {}
    for name, module in list(sys.modules.items()):
        if name.startswith("warptex.kernels"):
            values = list(vars(module).values())
            values += [v for d in values if isinstance(d, dict) for v in d.values()]  # stubs a factory made (lanes.splat_layers.FACE_LAYER_STUBS)
            for value in values:
                if isinstance(value, FUNCTION) and getattr(value, "native_snippet", None):
                    seen[f"{name}.{value.key}"] = value.native_snippet.split("#else")[0]
    return seen


def test_every_stub_calls_functions_the_headers_define():
    """The stubs are calls: each ``wt_*`` function a native function's CPU body calls is defined in a
    header, and no stub holds more than a few lines of C++."""
    defined = set()
    for header in HEADERS:
        defined |= set(re.findall(r"(?:WT_INLINE|WT_OUTLINE|inline)[^;{]*?\b(wt_\w+)\s*\(", header.read_text()))
    stubs = _stubs()
    assert len(stubs) >= 20
    for name, body in stubs.items():
        called = set(DEFINED.findall(body))
        assert called, f"{name} calls no header function"
        assert called <= defined, f"{name} calls {sorted(called - defined)}, which no header defines"
        assert body.count(";") <= 2, f"{name}: more than a call: {body}"


def _compile_alone(tmp_path, folder: Path, header: str, name: str):
    """Compile, on the CPU, a Warp module whose preamble is the constants and ``header`` (from
    ``folder``) alone."""
    module = f"warptex.test_native.{name}"
    options = wp.ModuleBuildOptions(
        extra_cpu_include_dirs=[str(folder)],
        extra_cpu_preamble=native.constants() + f'#include "{header}"\n',
        extra_build_dependencies=sorted(str(h) for h in folder.glob("*.h")),  # their text in the module's hash: an edit recompiles
    )
    wp.set_module_options({"extra_build_options": options}, module=module)

    @wp.kernel(module=module)
    def touch(x: wp.array(dtype=float)):
        x[wp.tid()] = 1.0

    wp.load_module(module, device="cpu")


@pytest.mark.parametrize("header", HEADERS, ids=lambda h: h.name)
def test_each_header_compiles_alone(tmp_path, header):
    """Each header includes what it uses: it compiles with the generated constants and nothing else."""
    _compile_alone(tmp_path, native.folder(), header.name, header.stem)


def test_a_compile_error_names_the_header_and_its_line(tmp_path, capfd):
    """A broken line in a header is reported at that header's line, not in Warp's generated .cpp."""
    folder = tmp_path / "native"
    shutil.copytree(native.folder(), folder, ignore=shutil.ignore_patterns("*.py", "__pycache__"))
    lines = (folder / "wt_taps.h").read_text().splitlines()
    broken = next(i for i, line in enumerate(lines) if "wt_lane_taps taps;" in line)
    lines[broken] += " int broken = not_declared_anywhere;"
    (folder / "wt_taps.h").write_text("\n".join(lines) + "\n")
    with pytest.raises(Exception):
        _compile_alone(tmp_path, folder, "wt_taps.h", "broken")
    err = capfd.readouterr().err
    assert f"wt_taps.h:{broken + 1}:" in err and "not_declared_anywhere" in err, err


def _clang_format():
    found = shutil.which("clang-format") or shutil.which("clang-format", path=str(Path(sys.executable).parent))
    if found is None:
        pytest.skip("clang-format is not installed (pip install clang-format: the test extra has it)")
    return found


def test_the_headers_are_formatted():
    """``clang-format --dry-run --Werror`` with the repository's ``.clang-format``: run
    ``clang-format -i kernels/native/*.h`` to fix a failure."""
    style = Path(__file__).resolve().parents[1] / ".clang-format"
    if not style.is_file():
        pytest.skip("no .clang-format beside the tests (an installed copy of the tests)")
    result = subprocess.run([_clang_format(), f"--style=file:{style}", "--dry-run", "--Werror", *map(str, HEADERS)], capture_output=True, text=True)
    assert result.returncode == 0, result.stderr[-3000:]
