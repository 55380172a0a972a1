"""Tests for training/render.py: coverage against geometry, the z-buffer, orientation, and input checks."""

import numpy as np
import pytest

from training import render as R
from training.render import MeshLayer, fit_camera, grid, render, render_views, save_png

BLUE, RED = (0.1, 0.2, 0.9), (0.9, 0.1, 0.1)
BG = (1.0, 1.0, 1.0)


def box(size=(1.0, 1.0, 1.0), center=(0.0, 0.0, 0.0)):
    """Closed axis-aligned box: (8, 3) vertices, (12, 3) faces wound counter-clockwise from outside."""
    corners = np.array([[x, y, z] for x in (-0.5, 0.5) for y in (-0.5, 0.5) for z in (-0.5, 0.5)])
    v = corners * np.asarray(size) + np.asarray(center)
    f = np.array(
        [[0, 1, 3], [0, 3, 2], [4, 6, 7], [4, 7, 5], [0, 4, 5], [0, 5, 1],
         [2, 3, 7], [2, 7, 6], [0, 2, 6], [0, 6, 4], [1, 5, 7], [1, 7, 3]]
    )  # fmt: skip
    # Orient every face outward (the centroid-to-face vector agrees with the normal).
    tri = v[f]
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    flip = np.einsum("fj,fj->f", n, tri.mean(1) - v.mean(0)) < 0
    f[flip] = f[flip][:, ::-1]
    return v, f


def square(half, y, color, normal_sign=-1):
    """Square in the plane y = const spanning [-half, half] in X and Z, facing -Y (normal_sign=-1) or +Y."""
    v = np.array([[-half, y, -half], [half, y, -half], [half, y, half], [-half, y, half]])
    f = np.array([[0, 1, 2], [0, 2, 3]])
    if normal_sign > 0:
        f = f[:, ::-1]
    return MeshLayer(v, f, color)


def plain(layers, view="front", size=200, **kw):
    """Rendering with nothing but the shaded surfaces, so that colours can be classified per pixel."""
    return render(layers, view, size, outline=False, supersample=1, background=BG, **kw)


def foreground(img):
    return np.any(img != np.asarray(BG), axis=-1)


def reddish(img):
    return foreground(img) & (img[..., 0] > img[..., 2])


def bluish(img):
    return foreground(img) & (img[..., 2] > img[..., 0])


# --- coverage against geometry -------------------------------------------------------------------


@pytest.mark.parametrize("view", ["front", "back", "side", "side_left"])
def test_unit_cube_silhouette_area(view):
    size, margin = 200, 0.05
    img = plain([MeshLayer(*box(), BLUE)], view, size)
    side = size * (1 - 2 * margin)  # auto-fit: the cube's 1 m side spans the image minus margins
    # Every boundary pixel may go either way: one perimeter's worth of pixels.
    assert abs(foreground(img).sum() - side**2) <= 4 * side


def test_rotated_cube_fits_projected_extent():
    """Turned 45 deg about Z, the cube is sqrt(2) wide in front view; the fit scales to that width."""
    v, f = box()
    c, s = np.cos(np.pi / 4), np.sin(np.pi / 4)
    v = v @ np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]]).T
    size = 200
    img = plain([MeshLayer(v, f, BLUE)], "front", size)
    width = size * 0.9
    height = width / np.sqrt(2)
    fg = foreground(img)
    assert abs(fg.sum() - width * height) <= 2 * (width + height)
    cols, rows = np.flatnonzero(fg.any(0)), np.flatnonzero(fg.any(1))
    assert abs(len(cols) - width) <= 2 and abs(len(rows) - height) <= 2


# --- z-buffer -------------------------------------------------------------------------------------


def test_near_small_square_hides_part_of_far_big_square():
    big, small = square(1.0, 0.0, BLUE), square(0.2, -0.5, RED)  # red nearer to the front camera
    size = 200
    for layers in ([big, small], [small, big]):  # drawing order must not matter
        img = plain(layers, "front", size)
        red_side = size * 0.9 * 0.2  # 0.4 m of a 2 m extent spanning 90 % of the image
        assert abs(reddish(img).sum() - red_side**2) <= 4 * red_side
        assert reddish(img)[size // 2, size // 2]
        assert bluish(img)[size // 10, size // 10]


def test_swapping_depth_order_hides_the_small_square():
    big, small_behind = square(1.0, 0.0, BLUE), square(0.2, 0.5, RED)
    img = plain([small_behind, big], "front")
    assert reddish(img).sum() == 0
    assert bluish(img).sum() > 0
    # Seen from behind, the red square is in front again.
    assert reddish(plain([small_behind, big], "back")).sum() > 0


def test_interpenetrating_boxes_show_both_colours():
    cube = MeshLayer(*box(), BLUE)
    rod = MeshLayer(*box((0.4, 2.0, 0.4)), RED)  # pokes out of the cube's front and back faces
    img = plain([cube, rod], "front", 200)
    assert reddish(img)[100, 100] and bluish(img)[40, 40]
    # Bounding the rod's footprint: 0.4 m of the cube's 1 m fit.
    red_side = 200 * 0.9 * 0.4
    assert abs(reddish(img).sum() - red_side**2) <= 4 * red_side


def test_box_fully_inside_another_is_hidden():
    cube = MeshLayer(*box(), BLUE)
    inner = MeshLayer(*box((0.4, 0.4, 0.4)), RED)
    for view in R.VIEWS:
        assert reddish(plain([inner, cube], view)).sum() == 0, view


def test_back_faces_are_darker():
    front_facing = plain([square(1.0, 0.0, BLUE, normal_sign=-1)], "front")
    back_facing = plain([square(1.0, 0.0, BLUE, normal_sign=+1)], "front")
    assert back_facing[100, 100].sum() < 0.75 * front_facing[100, 100].sum()


# --- orientation ----------------------------------------------------------------------------------


def test_view_orientation():
    """+X is image right in front view, -Y (where the body faces) is image right in side view,
    +Z is image top in both."""
    marker_x = MeshLayer(*box((0.2, 0.2, 0.2), (0.8, 0.0, 0.0)), RED)
    marker_z = MeshLayer(*box((0.2, 0.2, 0.2), (0.0, 0.0, 0.8)), BLUE)
    marker_front = MeshLayer(*box((0.2, 0.2, 0.2), (0.0, -0.8, 0.0)), RED)
    img = plain([marker_x, marker_z], "front")
    cols = np.flatnonzero(reddish(img).any(0))
    rows = np.flatnonzero(bluish(img).any(1))
    assert cols.min() > 100 and rows.max() < 100
    img = plain([marker_front, marker_z], "side")
    assert np.flatnonzero(reddish(img).any(0)).min() > 100
    img = plain([marker_front, marker_z], "side_left")
    assert np.flatnonzero(reddish(img).any(0)).max() < 100


@pytest.mark.parametrize("view", R.VIEWS)
def test_view_axes_are_orthonormal_and_right_handed(view):
    right, up, forward = R.view_axes(view)
    m = np.stack([right, up, -forward])
    np.testing.assert_allclose(m @ m.T, np.eye(3), atol=1e-12)
    assert np.linalg.det(m) == pytest.approx(1.0)
    assert up[2] > 0.9


# --- vectorised rasteriser against the one-triangle-at-a-time reference --------------------------


def random_triangles(rng, n, height, width):
    centers = rng.uniform([-10, -10], [width + 10, height + 10], size=(n, 1, 2))
    scales = rng.choice([0.7, 3.0, 12.0, 60.0], size=(n, 1, 1))
    xy = centers + rng.normal(size=(n, 3, 2)) * scales
    return xy, rng.uniform(0, 1, size=(n, 3))


@pytest.mark.parametrize("batch", [R._BATCH, 64])  # 64 forces many batches per size group
def test_rasterize_matches_reference(monkeypatch, batch):
    monkeypatch.setattr(R, "_BATCH", batch)
    rng = np.random.default_rng(0)
    xy, depth = random_triangles(rng, 300, 48, 64)
    fast, slow = R.rasterize(xy, depth, 48, 64), R.rasterize_reference(xy, depth, 48, 64)
    np.testing.assert_array_equal(fast.face, slow.face)
    np.testing.assert_allclose(fast.depth, slow.depth, atol=1e-9)
    np.testing.assert_allclose(fast.bary, slow.bary, atol=1e-9)
    assert (fast.face >= 0).mean() > 0.5  # the comparison covers a well-filled image


def test_grid_mesh_with_vertices_on_pixel_centres_has_no_holes():
    """Shared edges running exactly through pixel centres are the worst case for cracks."""
    n = 20
    gx, gy = np.meshgrid(np.arange(n + 1) * 2 + 0.5, np.arange(n + 1) * 2 + 0.5)
    pts = np.stack([gx.ravel(), gy.ravel()], -1)
    idx = np.arange((n + 1) ** 2).reshape(n + 1, n + 1)
    a, b, c, d = idx[:-1, :-1].ravel(), idx[:-1, 1:].ravel(), idx[1:, 1:].ravel(), idx[1:, :-1].ravel()
    faces = np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])
    raster = R.rasterize(pts[faces], np.zeros(faces.shape), 2 * n + 1, 2 * n + 1)
    assert np.all(raster.face >= 0)


# --- output contract ------------------------------------------------------------------------------


def test_render_output_shape_dtype_range():
    img = render([MeshLayer(*box(), R.PALETTE["denim"])], "three_quarter", 96)
    assert img.shape == (96, 96, 3) and img.dtype == np.float64
    assert img.min() >= 0 and img.max() <= 1
    np.testing.assert_allclose(img[0, 0], R.BACKGROUND)


def test_shared_camera_keeps_scale():
    small, large = MeshLayer(*box((0.5, 0.5, 0.5)), BLUE), MeshLayer(*box(), BLUE)
    cam = fit_camera([large], "front")
    a, b = plain([small], camera=cam), plain([large], camera=cam)
    assert foreground(a).sum() == pytest.approx(foreground(b).sum() / 4, rel=0.05)


def test_render_views_and_grid_shapes():
    layers = [MeshLayer(*box(), BLUE)]
    img = render_views(layers, ("front", "side", "back"), 64, title="t")
    assert img.shape == (64 + 40, 3 * 64, 3)
    assert render_views(layers, ("front",), 64).shape == (64, 64, 3)
    cells = [np.zeros((30, 40, 3)), np.ones((20, 50, 3)), np.zeros((30, 50, 3))]
    out = grid(cells, ["a", "b", "c"], columns=2, gap=4)
    assert out.shape == (2 * (30 + 32 + 4), 2 * (50 + 4), 3)


def test_save_png_round_trip(tmp_path):
    import matplotlib.image

    img = np.random.default_rng(1).uniform(size=(17, 23, 3))
    path = save_png(tmp_path / "sub" / "x.png", img)
    back = matplotlib.image.imread(path)[..., :3]
    np.testing.assert_allclose(back, img, atol=0.5 / 255 + 1e-6)


# --- input checks ---------------------------------------------------------------------------------

V, F = box()


@pytest.mark.parametrize(
    ("kwargs", "name"),
    [
        ({"vertices": V[:, :2], "faces": F, "color": BLUE}, "vertices"),
        ({"vertices": np.full((8, 3), np.nan), "faces": F, "color": BLUE}, "vertices"),
        ({"vertices": V, "faces": F.astype(float), "color": BLUE}, "faces"),
        ({"vertices": V, "faces": F + 1, "color": BLUE}, "faces"),
        ({"vertices": V, "faces": F, "color": (1.5, 0, 0)}, "color"),
        ({"vertices": V, "faces": F, "color": (1, 0)}, "color"),
    ],
)
def test_mesh_layer_rejects_bad_arrays(kwargs, name):
    with pytest.raises(ValueError, match=name):
        MeshLayer(**kwargs)


@pytest.mark.parametrize(
    ("call", "name"),
    [
        (lambda layer: render([layer], "top"), "view"),
        (lambda layer: render([layer], "front", 0), "size"),
        (lambda layer: render([layer], "front", 64.0), "size"),
        (lambda layer: render([], "front", 64), "layers"),
        (lambda layer: render(layer, "front", 64), "layers"),
        (lambda layer: render([layer, "mesh"], "front", 64), r"layers\[1\]"),
        (lambda layer: render([layer], "front", 64, supersample=0), "supersample"),
        (lambda layer: render_views([layer], "front", 64), "views"),
        (lambda layer: grid([np.zeros((4, 4, 3))], ["a", "b"], 1), "titles"),
        (lambda layer: grid([np.zeros((4, 4))], None, 1), r"images\[0\]"),
        (lambda layer: grid([np.zeros((4, 4, 3))], None, 0), "columns"),
        (lambda layer: save_png("/tmp/never.png", np.zeros((4, 4))), "image"),
        (lambda layer: R.rasterize(np.zeros((2, 3)), np.zeros((2, 3)), 4, 4), "xy"),
        (lambda layer: R.rasterize(np.zeros((2, 3, 2)), np.zeros((2,)), 4, 4), "depth"),
    ],
)
def test_bad_arguments_name_themselves(call, name):
    with pytest.raises(ValueError, match=name):
        call(MeshLayer(V, F, BLUE))
