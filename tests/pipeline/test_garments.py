"""Validity of every committed catalog garment (models/garments, rebuilt by
``python -m training.garments``): manifold with boundary, one loop per named opening,
normals away from the body, no self-intersections, no penetration of the mean body."""

import numpy as np
import pytest

from service.geometry.intersections import intersecting_pairs
from service.geometry.mesh import (
    boundary_loops,
    connected_components,
    edge_lengths,
    is_edge_manifold,
    vertex_normals,
)
from service.pipeline.body import DEFAULT_BETA, BodyModel
from service.pipeline.catalog import load_catalog

REQUIRED_IDS = {"tank_top", "tshirt", "long_sleeve", "jacket", "pants", "shorts", "skirt"}
OPENINGS = {
    "tank_top": {"neck", "armhole_l", "armhole_r", "hem"},
    "tshirt": {"neck", "sleeve_l", "sleeve_r", "hem"},
    "long_sleeve": {"neck", "sleeve_l", "sleeve_r", "hem"},
    "jacket": {"neck", "sleeve_l", "sleeve_r", "hem"},
    "pants": {"waist", "leg_l", "leg_r"},
    "shorts": {"waist", "leg_l", "leg_r"},
    "skirt": {"waist", "hem"},
}


@pytest.fixture(scope="module")
def catalog():
    return load_catalog()


@pytest.fixture(scope="module")
def mean_body():
    body = BodyModel.load()
    return body.vertices(np.array(DEFAULT_BETA)), body.faces


def test_catalog_has_the_seven_garments(catalog):
    assert set(catalog) == REQUIRED_IDS
    tops = [g for g in catalog.values() if g.category == "top"]
    ranks = {g.id: g.layer_rank for g in tops}
    assert ranks["tank_top"] < ranks["tshirt"] < ranks["long_sleeve"] < ranks["jacket"]


@pytest.mark.parametrize("gid", sorted(REQUIRED_IDS))
def test_manifold_single_piece(catalog, gid):
    g = catalog[gid]
    assert is_edge_manifold(g.faces)
    assert len(np.unique(connected_components(g.faces, len(g.vertices)))) == 1
    assert len(np.unique(g.faces)) == len(g.vertices)  # no unreferenced vertices


@pytest.mark.parametrize("gid", sorted(REQUIRED_IDS))
def test_one_boundary_loop_per_named_opening(catalog, gid):
    g = catalog[gid]
    assert set(g.openings) == OPENINGS[gid]
    loops = boundary_loops(g.faces)
    assert len(loops) == len(g.openings)
    as_sets = sorted(tuple(sorted(loop)) for loop in loops)
    assert as_sets == sorted(tuple(sorted(loop)) for loop in g.openings.values())


@pytest.mark.parametrize("gid", sorted(REQUIRED_IDS))
def test_edge_length_near_uniform(catalog, gid):
    lengths = edge_lengths(catalog[gid].vertices, catalog[gid].faces)
    assert 0.010 <= lengths.mean() <= 0.015
    assert np.percentile(lengths, 99) < 0.02
    assert lengths.min() > 0.003  # no slivers: they would stiffen the drape simulation


@pytest.mark.parametrize("gid", sorted(REQUIRED_IDS))
def test_normals_point_away_from_body(catalog, mean_body, gid):
    from scipy.spatial import cKDTree

    g = catalog[gid]
    bv, bf = mean_body
    body_normals = vertex_normals(bv, bf)
    _, nearest = cKDTree(bv).query(g.vertices)
    agree = np.einsum("nd,nd->n", vertex_normals(g.vertices, g.faces), body_normals[nearest]) > 0
    assert agree.mean() > 0.97


@pytest.mark.parametrize("gid", sorted(REQUIRED_IDS))
def test_no_self_intersections(catalog, gid):
    g = catalog[gid]
    assert len(intersecting_pairs(g.vertices, g.faces)) == 0


@pytest.mark.parametrize("gid", sorted(REQUIRED_IDS))
def test_does_not_penetrate_mean_body(catalog, mean_body, gid):
    import trimesh

    g = catalog[gid]
    bv, bf = mean_body
    # No garment triangle crosses a body triangle, and the garment is one piece, so it lies
    # entirely on one side of the closed body surface: checking a few vertices decides which.
    assert len(intersecting_pairs(g.vertices, g.faces, bv, bf)) == 0
    probes = g.vertices[:: max(1, len(g.vertices) // 50)]
    assert not trimesh.Trimesh(bv, bf, process=False).contains(probes).any()
