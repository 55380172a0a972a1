"""A display mesh embedded in a simulation mesh it is not made of (an imported garment remeshed for
the simulation): exact where it was built, it moves rigidly with a rigidly moved cloth and smoothly
with a bent one, survives the catalog's files and is what the GLB draws."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from service.geometry.closest import ClosestPoint
from service.geometry.mesh import vertex_normals
from service.pipeline.appearance import DisplayMesh, Embedding
from service.pipeline.catalog import load_catalog, save_garment
from service.pipeline.gltf import ANNY_TO_GLTF, GltfLayer, outfit_glb
from tests.conftest import tiny_garments
from tests.meshes import grid_mesh
from tests.pipeline.test_gltf import _read


def _wavy_display(n: int = 24, seed: int = 0):
    """A fine wavy sheet over the unit square, 1 mm above and below z = 0: points (D, 3), faces, uv."""
    v, f = grid_mesh(n)
    v = v.copy()
    v[:, 2] = 0.001 * np.sin(9 * v[:, 0]) * np.cos(7 * v[:, 1])
    return v, f, v[:, :2].astype(np.float32)


def _embedded(sim_n: int = 5):
    points, faces, uv = _wavy_display()
    sv, sf = grid_mesh(sim_n)
    q = ClosestPoint.build(sv, sf).query(points)
    e = Embedding.build(points, sv, sf, q.face, q.bary)
    source = sf[q.face, np.argmax(q.bary, axis=1)]
    return points, DisplayMesh(source, uv, faces, e), sv, sf


def test_the_embedding_is_exact_where_it_was_built():
    points, display, sv, sf = _embedded()
    display.check(len(sv), sf)
    placed, normals = display.place(sv, sf, vertex_normals(sv, sf))
    np.testing.assert_allclose(placed, points, atol=1e-7)  # offsets stored as float32 (~1e-3 m)
    np.testing.assert_allclose(normals, np.broadcast_to([0.0, 0.0, 1.0], normals.shape), atol=1e-12)


def test_the_display_moves_rigidly_with_rigidly_moved_cloth():
    points, display, sv, sf = _embedded()
    rotation = Rotation.from_euler("xyz", [0.4, -1.1, 2.0]).as_matrix()
    moved = sv @ rotation.T + [0.3, -0.2, 1.5]
    placed, normals = display.place(moved, sf, vertex_normals(moved, sf))
    np.testing.assert_allclose(placed, points @ rotation.T + [0.3, -0.2, 1.5], atol=1e-7)
    np.testing.assert_allclose(normals, np.broadcast_to(rotation[:, 2], normals.shape), atol=1e-12)


def test_bent_cloth_carries_the_display_without_tearing_it():
    """Bend the sheet around a cylinder: the simulation vertices land on it, so each 0.1 m face
    becomes a chord (shorter by 1 - sin(0.1) / 0.1 = 0.17 %) and each edge between faces a kink of
    0.1 / 0.5 = 0.2 rad. A display edge across a kink shortens as a bent path does (at most
    1 - cos(0.1) = 0.5 %) and its ends' offsets (at most 1 mm) turn apart by 0.2 rad over the
    shortest edge (1/24 m): 0.5 %. Nothing more may change it; and every display vertex stays within
    the chords' sag of the cylinder."""
    points, display, sv, sf = _embedded(sim_n=10)
    radius = 0.5

    def bend(x):
        angle = x[:, 0] / radius
        r = radius + x[:, 2]
        return np.stack([r * np.sin(angle), x[:, 1], r * np.cos(angle) - radius], axis=1)

    placed, _ = display.place(bend(sv), sf, vertex_normals(bend(sv), sf))
    edges = display.faces[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2)
    before = np.linalg.norm(points[edges[:, 0]] - points[edges[:, 1]], axis=1)
    after = np.linalg.norm(placed[edges[:, 0]] - placed[edges[:, 1]], axis=1)
    kink, shortest = 0.1 / radius, 1 / 24
    chord = 1 - np.sin(kink / 2) / (kink / 2)
    assert np.abs(after / before - 1).max() <= chord + (1 - np.cos(kink / 2)) + 0.001 * kink / shortest
    sag = radius * (1 - np.cos(0.1 * np.sqrt(2) / radius / 2))  # a face's diagonal as the chord
    assert np.linalg.norm(placed - bend(points), axis=1).max() <= sag + 0.001 * kink


def test_an_embedding_that_does_not_fit_is_refused():
    points, display, sv, sf = _embedded()
    e = display.embedding
    with pytest.raises(ValueError, match="embedding faces outside"):
        replace(display, embedding=Embedding(e.face + len(sf), e.bary, e.offset)).check(len(sv), sf)
    with pytest.raises(ValueError, match="do not fit"):
        replace(display, embedding=Embedding(e.face, e.bary[:, :2], e.offset)).check(len(sv), sf)
    nan = e.offset.copy()
    nan[0, 0] = np.nan
    with pytest.raises(ValueError, match="must be finite"):
        replace(display, embedding=Embedding(e.face, e.bary, nan)).check(len(sv), sf)
    with pytest.raises(ValueError, match="flip the garment before"):
        display.flipped()


def test_an_embedded_display_mesh_round_trips_and_is_what_the_glb_draws(tmp_path: Path):
    points, display, sv, sf = _embedded()
    garment = replace(tiny_garments()[0], vertices=sv, faces=sf, openings={}, display=display)
    save_garment(tmp_path, garment)
    (tmp_path / "catalog.json").write_text(json.dumps({"garments": [garment.catalog_entry()]}))
    loaded = load_catalog(tmp_path)[garment.id].display
    for key in ("face", "bary", "offset"):
        np.testing.assert_array_equal(getattr(loaded.embedding, key), getattr(display.embedding, key))
    np.testing.assert_array_equal(loaded.faces, display.faces)
    moved = sv + [0.0, 0.0, 0.1]
    doc, accessor, _ = _read(outfit_glb([GltfLayer("tshirt", moved, sf, loaded)]))
    primitive = doc["meshes"][0]["primitives"][0]["attributes"]
    np.testing.assert_allclose(accessor(primitive["POSITION"]), (points + [0, 0, 0.1]) @ ANNY_TO_GLTF.T,
                               atol=1e-6)  # fmt: skip
    np.testing.assert_array_equal(accessor(primitive["TEXCOORD_0"]), display.uv)
    assert len(accessor(primitive["NORMAL"])) == len(points)
