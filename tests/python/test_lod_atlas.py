"""GetLod's texture coordinates (issue #37): level 0 of a model that stores a texture atlas
(`animspace atlas`), fetched with ``get_lod(..., texture_coordinates=True)``, carries the atlas
per face corner, and so does every level of a model whose levels were built under its atlas
(`atlas`, then `build-lod`). Checked against the atlas read independently: the C++ CLI's offline
``animspace export-lod --level L`` of the same file, whose OBJ has the UVs as ``vt`` with the
seams split, corner for corner.
"""
import pathlib
import subprocess

import numpy as np
import pytest

import animspace

from conftest import BUILD, run_animspaced

CLI = BUILD / "bin" / "animspace"
MODEL = "arm-animspace"  # the demo's, with an atlas (its levels built before it: no UVs)
PLAIN = "arm-plain"      # the same model without one
LEVELS = "arm-levels"    # the atlas'd model with levels built again under its atlas


def _run(*arguments):
    done = subprocess.run([str(CLI), *map(str, arguments)], capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stdout + done.stderr
    return done.stdout


@pytest.fixture(scope="module")
def atlas_repository(tmp_path_factory):
    work = tmp_path_factory.mktemp("atlas")
    _run("demo-repository", work / "demo")
    source = work / "demo" / MODEL / "1" / "model.anim"
    repository = work / "repository"
    (repository / MODEL / "1").mkdir(parents=True)
    (repository / PLAIN / "1").mkdir(parents=True)
    (repository / PLAIN / "1" / "model.anim").write_bytes(source.read_bytes())
    _run("atlas", source, "-o", repository / MODEL / "1" / "model.anim")
    (repository / LEVELS / "1").mkdir(parents=True)
    _run("build-lod", repository / MODEL / "1" / "model.anim", "-o", repository / LEVELS / "1" / "model.anim")
    return repository


@pytest.fixture(scope="module")
def atlas_client(atlas_repository, tmp_path_factory):
    with run_animspaced(tmp_path_factory.mktemp("atlas-daemon"), "--model-repository", str(atlas_repository)) as address, \
            animspace.Client(address) as client:
        client.wait_until_serving(deadline_s=60)
        yield client


def _read_obj(path: pathlib.Path):
    """Corners of an OBJ written with vt: (position, uv) per face corner, rows of 5 float64."""
    v, vt, corners = [], [], []
    for line in path.read_text().splitlines():
        parts = line.split()
        if not parts:
            continue
        if parts[0] == "v":
            v.append([float(x) for x in parts[1:4]])
        elif parts[0] == "vt":
            vt.append([float(x) for x in parts[1:3]])
        elif parts[0] == "f":
            for corner in parts[1:4]:
                index = corner.split("/")
                corners.append(v[int(index[0]) - 1] + vt[int(index[1]) - 1])
    return np.array(corners, dtype=np.float64)


def _sorted_rows(rows: np.ndarray) -> np.ndarray:
    return rows[np.lexsort(rows.T[::-1])]


def test_level_0_carries_the_stored_atlas_per_corner(atlas_client, atlas_repository, tmp_path):
    plain = atlas_client.get_lod(MODEL, level=0)
    assert plain.texture_coordinates is None and not plain.header.texture_coordinates
    mesh = atlas_client.get_lod(MODEL, level=0, texture_coordinates=True, vertices_per_chunk=100)
    uvs = mesh.texture_coordinates
    assert mesh.header.texture_coordinates
    assert uvs.dtype == np.float32 and uvs.shape == (mesh.face_count, 3, 2)
    assert np.all((uvs >= 0) & (uvs <= 1))
    # The mesh is the one without UVs: per-corner UVs leave the vertices alone.
    np.testing.assert_array_equal(mesh.positions, plain.positions)
    np.testing.assert_array_equal(mesh.indices, plain.indices)

    # The CLI's offline export of the same file: every corner's position and UV.
    obj = tmp_path / "level0.obj"
    _run("export-lod", atlas_repository / MODEL / "1" / "model.anim", "--level", "0", "-o", obj)
    expected = _read_obj(obj)
    served = np.concatenate([mesh.positions[mesh.indices.astype(np.int64)].reshape(-1, 3),
                             uvs.reshape(-1, 2)], axis=1).astype(np.float64)
    assert served.shape == expected.shape
    np.testing.assert_allclose(_sorted_rows(served), _sorted_rows(expected), rtol=0, atol=1e-6)
    # A seam: some vertex has corners with different UVs (an atlas of disc charts has seams).
    per_vertex = {}
    for vertex, uv in zip(mesh.indices.reshape(-1).tolist(), map(tuple, uvs.reshape(-1, 2).tolist())):
        per_vertex.setdefault(vertex, set()).add(uv)
    assert any(len(found) > 1 for found in per_vertex.values())


def test_every_level_built_under_the_atlas_carries_its_uvs(atlas_client, atlas_repository, tmp_path):
    levels = atlas_client.describe_model(LEVELS).default.lod_level_count
    assert levels > 2
    for level in range(levels):
        mesh = atlas_client.get_lod(LEVELS, level=level, texture_coordinates=True, vertices_per_chunk=64)
        assert mesh.header.texture_coordinates and mesh.header.level == level
        uvs = mesh.texture_coordinates
        assert uvs.shape == (mesh.face_count, 3, 2) and np.all((uvs >= 0) & (uvs <= 1))
        obj = tmp_path / f"level{level}.obj"
        _run("export-lod", atlas_repository / LEVELS / "1" / "model.anim", "--level", level, "-o", obj)
        expected = _read_obj(obj)
        served = np.concatenate([mesh.positions[mesh.indices.astype(np.int64)].reshape(-1, 3),
                                 uvs.reshape(-1, 2)], axis=1).astype(np.float64)
        assert served.shape == expected.shape, f"level {level}"
        np.testing.assert_allclose(_sorted_rows(served), _sorted_rows(expected), rtol=0, atol=1e-6,
                                   err_msg=f"level {level}")


def test_refusals_name_include_texture_coordinates(atlas_client):
    levels = atlas_client.describe_model(MODEL).default.lod_level_count
    assert levels > 1
    with pytest.raises(animspace.FailedPrecondition) as error:
        atlas_client.get_lod(MODEL, level=1, texture_coordinates=True)
    assert (f"include_texture_coordinates: level 1 of model '{MODEL}' version 1 stores no texture coordinates"
            in error.value.message)
    with pytest.raises(animspace.InvalidArgument) as error:
        atlas_client.get_lod(MODEL, level=0, form="animation_space", texture_coordinates=True)
    assert "include_texture_coordinates: expected FORM_POSED" in error.value.message
    with pytest.raises(animspace.FailedPrecondition) as error:
        atlas_client.get_lod(PLAIN, level=0, texture_coordinates=True)
    assert f"include_texture_coordinates: model '{PLAIN}' version 1 stores no texture atlas" in error.value.message
