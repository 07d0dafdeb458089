"""Shared fixtures: Warp set-up, the shared data folder, and finite-difference helpers."""

from pathlib import Path

import numpy as np
import pytest
import warp as wp

wp.config.log_level = wp.LOG_WARNING
wp.init()

SHARED_DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data"


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
