"""Atlases that never take the process down (issue 52): xatlas in a process of its own, and
projected charts (warptex.charts) for meshes too large for xatlas or where it crashes."""

import importlib
import json
import subprocess
import sys

import numpy as np
import pytest
import trimesh
from conftest import face_charts

import warptex as wt
from warptex.charts import MERGE_FACING, projected_atlas
from warptex.unwrap import face_areas, unusable_reason

unwrap_module = importlib.import_module("warptex.unwrap")  # the module (warptex.unwrap is the function)


def _scan(subdivisions: int = 5, noise: float = 0.1, seed: int = 0) -> trimesh.Trimesh:
    """A scan-like rock: an icosphere (20·4^subdivisions faces) displaced by bumps of several
    sizes, with overhangs, and by noise of ``noise`` times the mean edge length (a scan's)."""
    mesh = trimesh.creation.icosphere(subdivisions=subdivisions)
    rng = np.random.default_rng(seed)
    v = mesh.vertices
    bumps = sum(a * np.sin(v @ rng.normal(size=3) * f + rng.uniform(0, 6)) for a, f in ((0.25, 2.0), (0.12, 5.0), (0.05, 11.0), (0.02, 29.0)))
    edge = np.linalg.norm(v[mesh.faces[:, 0]] - v[mesh.faces[:, 1]], axis=1).mean()
    v = v * (1.0 + bumps)[:, None] + rng.normal(size=v.shape) * noise * edge
    return trimesh.Trimesh(v, mesh.faces, process=False)


@pytest.mark.parametrize("mesh", ["icosphere", "scan", "bunny"])
def test_projected_charts_cover_every_face_without_overlap_flip_or_lost_area(mesh, request):
    if mesh == "bunny":
        mesh = wt.load_mesh(request.getfixturevalue("shared_data") / "meshes" / "bunny.ply")
    else:
        mesh = trimesh.creation.icosphere(subdivisions=4) if mesh == "icosphere" else _scan()
    v, f = np.asarray(mesh.vertices, np.float64), np.asarray(mesh.faces, np.int64)
    size, padding = 1024, 6
    vertex_map, faces, uv = projected_atlas(v, f, size, padding, overlaps=lambda uv, faces: unwrap_module.overlapping_faces(uv, faces, np.ones(len(faces), bool)) >= 0)
    assert (vertex_map[faces] == f).all()  # face k is face k
    assert uv.dtype == np.float32 and uv.min() >= 0 and uv.max() <= 1
    assert unusable_reason(uv, v[vertex_map], faces) == ""  # no two triangles overlap
    world, texture = face_areas(v[vertex_map], faces, uv)
    has_area = world > 1e-12 * world.max()
    assert (texture[has_area] > 0).all()
    # No triangle is flipped (every chart keeps the orientation of its faces), and texel density
    # varies by at most the projection's 1/MERGE_FACING between faces (1/MIN_FACING in large charts).
    e1, e2 = uv[faces[:, 1]] - uv[faces[:, 0]], uv[faces[:, 2]] - uv[faces[:, 0]]
    signed = e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]
    assert (signed[has_area] > 0).all()
    density = texture[has_area] / world[has_area]
    assert density.max() / density.min() <= 1 / MERGE_FACING * 1.001
    # Charts stay `padding` texels apart: no texel is within padding/2 of two charts' triangles.
    chart = face_charts(faces, len(uv))
    assert len(np.unique(chart)) < len(f) / 20, "charts are fragmented"
    boxes = {}
    for c in np.unique(chart):
        p = uv[faces[chart == c]].reshape(-1, 2) * size
        boxes[c] = (p.min(0), p.max(0))
    ordered = list(boxes.values())
    for i, (lo_a, hi_a) in enumerate(ordered):
        for lo_b, hi_b in ordered[i + 1 :]:
            gap = np.maximum(lo_b - hi_a, lo_a - hi_b).max()
            assert gap >= padding - 1e-3, f"two charts' boxes {gap:.2f} texels apart"


def test_large_meshes_get_projected_charts_and_say_why():
    mesh = trimesh.creation.icosphere(subdivisions=6)  # 81 920 faces: the mesh xatlas 0.0.11 crashes on
    layout = wt.unwrap(mesh, size=1024, padding=4)
    assert layout.source == "projection" and "81920 faces, more than xatlas unwraps" in layout.note
    assert layout.reason == "the mesh has no UVs"
    assert unusable_reason(layout.uv, layout.vertices, layout.faces) == ""


def test_a_crash_of_xatlas_is_an_error_not_a_dead_process():
    """The icosphere of 81 920 faces crashes xatlas 0.0.11 (SIGSEGV in PackCharts): in its own
    process, the caller gets a ValueError saying so and what to do."""
    with pytest.raises(ValueError, match=r"unwrap\(\): xatlas crashed \(SIGSEGV\) on this mesh; unwrap with atlas='projection'"):
        wt.unwrap(trimesh.creation.icosphere(subdivisions=6), size=1024, atlas="xatlas")


def test_where_xatlas_dies_auto_falls_back_to_projected_charts(tmp_path, monkeypatch):
    dying = tmp_path / "dying.py"
    dying.write_text("import os, signal\nos.kill(os.getpid(), signal.SIGSEGV)\n")
    monkeypatch.setattr(unwrap_module, "_CHILD", str(dying))
    layout = wt.unwrap(trimesh.creation.icosphere(subdivisions=2), size=256, padding=4)
    assert layout.source == "projection" and layout.note == "xatlas crashed (SIGSEGV) on this mesh"
    slow = tmp_path / "slow.py"
    slow.write_text("import time\ntime.sleep(30)\n")
    monkeypatch.setattr(unwrap_module, "_CHILD", str(slow))
    monkeypatch.setattr(unwrap_module, "XATLAS_MIN_TIMEOUT", 0.5)
    layout = wt.unwrap(trimesh.creation.icosphere(subdivisions=2), size=256, padding=4)
    assert layout.source == "projection" and layout.note == "xatlas did not finish within 0.5 s, twice"


def test_a_stalled_xatlas_is_tried_once_more(tmp_path, monkeypatch):
    """xatlas's process stalled twice here on an 80-face sphere it unwraps in 0.15 s (then not in
    500 tries): the bake fell back to projected charts after 600 s, and its gradient test failed.
    A stall now costs a minute for a small mesh, then xatlas runs once more (it gives the same
    atlas every time); only a second stall falls back."""
    mesh = trimesh.creation.icosphere(subdivisions=1)
    want = wt.unwrap(mesh, size=64, padding=2)
    runs, run = [], unwrap_module.subprocess.run

    def stalls_once(*args, timeout, **kwargs):
        runs.append(timeout)
        if len(runs) == 1:
            raise unwrap_module.subprocess.TimeoutExpired(args[0], timeout)
        return run(*args, timeout=timeout, **kwargs)

    monkeypatch.setattr(unwrap_module.subprocess, "run", stalls_once)
    got = wt.unwrap(mesh, size=64, padding=2)
    assert got.source == "xatlas" and runs == [60.0, 60.0]
    np.testing.assert_array_equal(got.uv, want.uv)
    assert unwrap_module.xatlas_timeout(50_000) == 600.0 and 60.0 < unwrap_module.xatlas_timeout(30_000) < 600.0


def test_xatlas_still_refuses_what_it_cannot_pack():
    with pytest.raises(ValueError, match=r"unwrap\(\): xatlas cannot pack this mesh's charts into 16² texels"):
        wt.unwrap(trimesh.creation.icosphere(subdivisions=1), size=16, padding=8)
    with pytest.raises(ValueError, match=r"unwrap\(\): projected charts cannot unwrap this mesh: .* cannot be packed into 16² texels"):
        wt.unwrap(trimesh.creation.icosphere(subdivisions=3), size=16, padding=8, atlas="projection")
    with pytest.raises(ValueError, match=r"unwrap\(\): atlas must be one of 'auto', 'xatlas', 'projection', got 'smart'"):
        wt.unwrap(trimesh.creation.icosphere(subdivisions=1), atlas="smart")


@pytest.mark.parametrize("mesh", ["icosphere", "scan"])
def test_the_icosphere_that_crashed_and_a_scan_bake_into_valid_glbs(tmp_path, mesh):
    """warptex bake of an icosphere of 327 680 faces (subdivisions 7; 6 crashed xatlas and the
    process with it) and of a scan-like rock of as many: GLBs the Khronos validator passes."""
    from test_bake import _gltf_validator

    path = tmp_path / "ico.obj"
    (trimesh.creation.icosphere(subdivisions=7) if mesh == "icosphere" else _scan(7)).export(path)
    out = tmp_path / "out" / "ico.glb"
    done = subprocess.run([sys.executable, "-m", "warptex", "bake", "--mesh", str(path), "--size", "512", "--out", str(out)], capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr
    assert sorted(p.name for p in out.parent.iterdir()) == ["ico.glb", "ico_color.png"]
    mesh, textures = wt.gltf.load_gltf(out)
    assert len(mesh.faces) == 327_680 and textures["color"].shape == (512, 512, 3)
    validator = _gltf_validator()
    if validator is None:
        pytest.skip("Node.js or the gltf-validator npm package is missing (.ci/run installs it: npm install --prefix .gltf-validator gltf-validator)")
    script = (
        "const v = require(process.argv[1]); const fs = require('fs');"
        "v.validateBytes(new Uint8Array(fs.readFileSync(process.argv[2]))).then(r => console.log(JSON.stringify(r.issues)))"
    )
    result = subprocess.run(["node", "-e", script, str(validator), str(out)], capture_output=True, text=True, timeout=300)
    issues = json.loads(result.stdout)
    assert issues["numErrors"] == 0 and issues["numWarnings"] == 0, json.dumps(issues["messages"])[:2000]
