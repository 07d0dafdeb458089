"""Shared fixtures: Warp set-up, the shared data folder, and finite-difference helpers."""

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
