"""Shared fixtures: Warp set-up, the shared data folder, and helpers several test modules use."""

from pathlib import Path

import numpy as np
import pytest
import warp as wp

wp.config.log_level = wp.LOG_WARNING
wp.init()

SHARED_DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data"
REPO_OUT = Path(__file__).resolve().parents[1] / "out"


def _snapshot(folder: Path) -> dict:
    return {p: p.stat().st_mtime_ns for p in folder.rglob("*")} if folder.is_dir() else {}


@pytest.fixture(scope="session", autouse=True)
def repository_out_is_left_alone():
    """Tests write under ``tmp_path``: the repository's ``out/`` is the user's render folder (issue
    34 found the suite writing ``out/sixplanar_sphere.png`` there). Any file a test run adds to or
    changes in it is an error of the session."""
    before = _snapshot(REPO_OUT)
    yield
    changed = sorted(str(p) for p, t in _snapshot(REPO_OUT).items() if before.get(p) != t)
    assert not changed, f"tests wrote into the repository's out/ (write under tmp_path): {changed}"


@pytest.fixture(scope="session", autouse=True)
def compiled_kernels():
    """Every warptex kernel compiled (or loaded from Warp's kernel cache) before the first test,
    side by side on every core: with a cold cache, tests would compile them one after another."""
    import warptex

    warptex.precompile("cpu", layer_counts=(4, 8))


@pytest.fixture
def shared_data() -> Path:
    """``../shared/data`` next to the repository; tests using it skip when it is absent."""
    if not SHARED_DATA.is_dir():
        pytest.skip(f"../shared/data not found at {SHARED_DATA}: real-data tests need the shared folder")
    return SHARED_DATA


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(1234)


SAMPLER_FIELDS = ("filter", "address", "border", "lod_bias", "min_lod", "max_lod", "max_aniso")


def with_sampler(kw: dict) -> dict:
    """Keyword arguments with the ``warptex.Sampler`` fields among them gathered into ``sampler=``
    (tests list sampler options beside a technique's own, as tables of cases)."""
    kw = dict(kw)
    fields = {k: kw.pop(k) for k in SAMPLER_FIELDS if k in kw}
    if fields:
        import warptex

        kw["sampler"] = warptex.Sampler(**fields)
    return kw


def face_charts(faces: np.ndarray, count: int) -> np.ndarray:
    """Each face's chart of an atlas with ``count`` vertices: faces joined through shared atlas
    vertices (union-find), one representative vertex index per face."""
    parent = np.arange(count)

    def root(i):
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    for a, b, c in faces:
        for x, y in ((a, b), (a, c)):
            parent[root(x)] = root(y)
    return np.array([root(f[0]) for f in faces])


def triplanar_backward(g, texture, tiling, weights: np.ndarray) -> wp.Tape:
    """``warptex.triplanar(g, texture, tiling=tiling)`` recorded on a tape (with the texture's mip
    chain update) and taken backward from the output gradient ``weights``; returns the tape. The
    gradients land in ``texture.grad(k)`` and ``tiling.grad``."""
    import warptex

    tape = wp.Tape()
    with tape:
        texture.update()
        out = warptex.triplanar(g, texture, tiling=tiling)
    out.grad.assign(weights)
    tape.backward()
    return tape


def normal_mapping(biplanar: bool):
    """``warptex.biplanar_normal`` or ``warptex.triplanar_normal``: the function a test case's
    ``biplanar`` flag picks (the references take the flag)."""
    import warptex

    return warptex.biplanar_normal if biplanar else warptex.triplanar_normal
