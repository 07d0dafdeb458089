"""One API vocabulary: the new spellings, and the old ones, which keep working for one release with
a ``DeprecationWarning`` that names the new one and give the same bits.

- biplanar normals are a function, ``biplanar_normal``, as biplanar colour is ``biplanar``
  (``triplanar_normal(biplanar=True)`` before);
- splat's per-face layers are ``layers_per_face``, as triplanar's ``textures_per_face``
  (``face_layers`` before);
- ``stochastic(..., stochastic=)`` takes the ``Stochastic`` every technique takes under that name
  (``method=`` before);
- internal helpers are underscored (``_as_sampler``, ``_as_stochastic``, ``_checked_size``,
  ``_gbuffer_device``, ``_as_splat_maps``).
"""

from __future__ import annotations

import importlib
import sys
import warnings

import numpy as np
import pytest

import warptex as wt


@pytest.fixture(scope="module")
def scene():
    """A G-buffer of a sphere seen from above, a normal map and a colour texture."""
    import trimesh

    mesh = trimesh.creation.icosphere(subdivisions=3)
    mesh.visual = trimesh.visual.TextureVisuals(uv=0.5 + 0.5 * mesh.vertices[:, [0, 2]])  # splat maps need UVs
    g = wt.rasterize(mesh, wt.orthographic((2.0, 3.0, 2.5), (0, 0, 0), height=2.4, resolution=(40, 48)))
    rng = np.random.default_rng(3)
    normal_map = np.concatenate([rng.uniform(0.3, 0.7, (16, 16, 2)), np.ones((16, 16, 1))], axis=-1).astype(np.float32)
    return g, wt.Texture(normal_map), wt.Texture(rng.random((16, 16, 3)).astype(np.float32))


def _no_warning(call):
    with warnings.catch_warnings():
        warnings.simplefilter("error", DeprecationWarning)
        return call()


def test_biplanar_normal_is_triplanar_normal_with_biplanar_weights(scene):
    g, normal_map, _ = scene
    new = _no_warning(lambda: wt.biplanar_normal(g, normal_map, sharpness=4.0, blend="rnm", tiling=1.3).numpy())
    with pytest.warns(DeprecationWarning, match=r"triplanar_normal\(biplanar=\.\.\.\) is deprecated .*: use warptex\.biplanar_normal"):
        old = wt.triplanar_normal(g, normal_map, biplanar=True, blend="rnm", tiling=1.3).numpy()
    np.testing.assert_array_equal(new, old)
    assert not np.array_equal(new, _no_warning(lambda: wt.triplanar_normal(g, normal_map, blend="rnm", tiling=1.3).numpy()))
    default = _no_warning(lambda: wt.biplanar_normal(g, normal_map).numpy())  # Quilez' sharpness 8, as biplanar's
    np.testing.assert_array_equal(default, wt.biplanar_normal(g, normal_map, sharpness=8.0).numpy())
    with pytest.raises(TypeError, match=r"biplanar_normal\(\) got an unexpected keyword argument 'sharpnes' \(its options are triplanar_normal\(\)'s"):
        wt.biplanar_normal(g, normal_map, sharpnes=3.0)
    with pytest.raises(ValueError, match=r"biplanar_normal\(\): strength must be >= 0"):
        wt.biplanar_normal(g, normal_map, strength=-1.0)


def test_stochastic_takes_stochastic_under_its_own_name(scene):
    *_, texture = scene
    uv = np.random.default_rng(4).uniform(-3, 3, (300, 2)).astype(np.float32)
    option = wt.Stochastic("hex", seed=7)
    new = _no_warning(lambda: wt.stochastic(texture, uv, stochastic=option, lod=0.5).numpy())
    np.testing.assert_array_equal(new, wt.stochastic(texture, uv, option, lod=0.5).numpy())
    with pytest.warns(DeprecationWarning, match=r"stochastic\(method=\.\.\.\) is deprecated .*: use stochastic\(stochastic=\.\.\.\)"):
        old = wt.stochastic(texture, uv, method=option, lod=0.5).numpy()
    np.testing.assert_array_equal(new, old)
    with pytest.raises(TypeError, match=r"stochastic\(\): got stochastic= and its old name method="):
        wt.stochastic(texture, uv, "hex", method="cheap2")


def test_splat_layers_per_face_is_named_as_textures_per_face(scene):
    g, *_ = scene
    rng = np.random.default_rng(5)
    layers = wt.TextureArray(rng.random((3, 16, 16, 4)).astype(np.float32))
    maps = wt.TextureArray(rng.random((1, 8, 8, 3)).astype(np.float32))
    per_face = [(None, None, None, 2, None, None), None, (0, 1, 0, 1, 0, 1)]
    kw = dict(projection="triplanar", tiling=0.7)
    new = _no_warning(lambda: wt.splat(g, layers, maps, layers_per_face=per_face, **kw).numpy())
    assert not np.array_equal(new, wt.splat(g, layers, maps, **kw).numpy())
    with pytest.warns(DeprecationWarning, match=r"splat\(face_layers=\.\.\.\) is deprecated .*: use splat\(layers_per_face=\.\.\.\)"):
        old = wt.splat(g, layers, maps, face_layers=per_face, **kw).numpy()
    np.testing.assert_array_equal(new, old)
    with pytest.raises(TypeError, match=r"splat\(\): got layers_per_face= and its old name face_layers="):
        wt.splat(g, layers, maps, layers_per_face=per_face, face_layers=per_face, **kw)


@pytest.mark.parametrize(
    "module, old",
    [("warptex.options", "as_sampler"), ("warptex.options", "as_stochastic"), ("warptex.unwrap", "checked_size"), ("warptex.gbuffer", "gbuffer_device"), ("warptex.splat", "as_splat_maps")],
)
def test_internal_helpers_are_underscored(module, old):
    importlib.import_module(module)
    namespace = sys.modules[module]  # (warptex.unwrap and warptex.splat are also functions of the package)
    with pytest.warns(DeprecationWarning, match=rf"{module}\.{old} is deprecated .*: use {module}\._{old}, an internal helper"):
        helper = getattr(namespace, old)
    assert helper is getattr(namespace, f"_{old}")
    with pytest.raises(AttributeError, match=rf"module '{module}' has no attribute 'no_such_name'"):
        namespace.no_such_name


def test_a_caller_name_is_spelt_func():
    """Every argument check takes the caller's name as ``func`` (not ``fn`` or ``who``)."""
    import inspect

    import warptex._files
    import warptex._validate
    import warptex.exr

    for module in (warptex._files, warptex._validate, warptex.exr):
        for name, function in inspect.getmembers(module, inspect.isfunction):
            if function.__module__ == module.__name__:
                assert not {"fn", "who"} & set(inspect.signature(function).parameters), f"{module.__name__}.{name}"
