"""features: each image's views described once into the tables that both orders read."""

from __future__ import annotations

import numpy as np
import pytest

from scalematch import Config
from scalematch.search.features import (IDENTITY_COARSER_POINTS, VIEWS_COARSER_POINTS, Describing,
                                 Roles, Table, image_views)
from scalematch.search.modes import mode_of
from scalematch.stages.descriptors import Described
from scalematch.stages.detector import image_contrast
from scalematch.stages.views import ViewParams, identity_view, view_plan


def describing(image: np.ndarray, config: Config = Config()) -> Describing:
    c = config
    return Describing(mode_of(c).describe, c.harris, c.harris_low,
                      image_contrast(image, c.harris),
                      dict(sigma=c.harris.sigma, min_level_sigma=c.harris.min_level_sigma,
                           decimate=c.harris.decimate, camera_blur_px=c.harris.camera_blur_px),
                      c.probe.points, c.views.edge_margin_px, c.views.vote_every,
                      c.harris.min_level_side_px, c.views.finer_from_scale)


def test_a_pass_describes_each_view_once_for_both_roles(raccoon):
    """The views of the first pass (t = 2, five longitudes): each one's levels probed from
    scale 2 on as the finer image, and its first level (its 500 strongest points) as the
    coarser one; the image itself comes from the plain search's description, its 1,500
    strongest."""
    image = raccoon[:360, :480].copy()
    plain = Described(1.0, np.zeros((3, 2)), np.array([0, 1, 2000]), np.zeros(3),
                      np.ones((3, 128), np.float32))
    keys = view_plan(ViewParams())[0]
    roles = Roles(identity_view(image), [], plain, Config().scales, True)
    views = image_views(image, None, roles, keys, ViewParams(), describing(image))
    assert [(v.tilt, v.longitude_deg) for v in views.views] == [(1.0, 0.0)] + keys
    assert views.views[1].scale == 1.0  # 360 px: viewed at full resolution
    # as the coarser image: the first level of every view, the image itself's strongest
    first = views.coarser
    assert set(first.view.tolist()) == set(range(len(keys) + 1))
    assert np.count_nonzero(first.view == 0) == 2  # the point ranked 2000th is left out
    assert 2000 > IDENTITY_COARSER_POINTS
    per_view = np.bincount(first.view)
    assert per_view[1:].max() <= 2 * VIEWS_COARSER_POINTS  # a point at two orientations
    assert np.all(first.s == 1.0)
    # as the finer image: only the tilted views' levels from scale 2 on, the probe's points
    f = views.finer
    assert set(f.view.tolist()) <= set(range(1, len(keys) + 1)) and len(f)
    assert f.s.min() >= 2.0 - 1e-9
    assert f.desc.shape[1] == first.desc.shape[1] == 128


def test_an_image_never_the_coarser_one_has_no_coarser_table(raccoon):
    image = raccoon[:300, :400].copy()
    roles = Roles(identity_view(image), [], None, Config().scales, False)
    views = image_views(image, None, roles, view_plan(ViewParams())[0], ViewParams(),
                        describing(image))
    assert len(views.coarser) == 0 and len(views.finer) > 0


def test_a_large_image_is_viewed_shrunk(raccoon):
    """An image whose shorter side is over ``max_short_side_px``: its views are made from it
    shrunk, each view pixel that many image pixels."""
    image = raccoon[:600, :800].copy()
    roles = Roles(identity_view(image), [], None, Config().scales, False)
    params = ViewParams(max_short_side_px=300.0)
    views = image_views(image, None, roles, view_plan(params)[0], params, describing(image))
    assert all(v.scale == pytest.approx(2.0) for v in views.views[1:])
    assert views.views[0].scale == 1.0


def test_the_strongest_rows_keep_the_strongest_points_and_both_their_orientations():
    d = Described(1.0, np.arange(10.0).reshape(5, 2), np.array([0, 0, 1, 2, 3]), np.zeros(5),
                  np.eye(5, 4, dtype=np.float32))
    kept = d.of_strongest(2)
    assert kept.index.tolist() == [0, 0, 1] and kept.xy.shape == (3, 2)


def test_a_table_counts_a_point_at_two_orientations_once():
    d = Described(2.0, np.zeros((3, 2)), np.array([0, 0, 1]), np.array([0.0, 1.0, 0.0]),
                  np.ones((3, 4), np.float32))
    t = Table.of([(1, d), (2, d)], 4)
    assert len(t) == 6 and len(set(t.point.tolist())) == 4
    assert t.rows(t.view == 2).view.tolist() == [2, 2, 2]
