"""The demo's illumination model from Python (Meyer & Anderson 2007 §3.2): lights in, the RGB
radiance of every surface point out, through the soft cache; the server gathers the key points
and fails through to its own full gather for lights the training never covered."""
import numpy as np
import pytest

import animspace

CORNELL = "cornell"
INSIDE = [0.2, 0.44, 0.45]   # in the plane of the training grid, between its lights
FLOOR = [0.5, 0.03, 0.5]     # at floor level: far outside the training grid


def test_the_model_says_it_fails_through_to_an_illumination_engine(client):
    version = client.describe_model(CORNELL).default
    assert version.kind == "PMSC" and version.channel_count == 3
    assert version.fail_through == "SERVER" and version.server_engine == "ILLUMINATION"
    assert client.describe_model("arm-pmsc").default.server_engine == "UNSPECIFIED"


def test_a_relit_frame_is_the_subspace_answer_for_the_keys_the_server_gathered(client):
    lit = client.relight(CORNELL, INSIDE)
    keys = client.describe_key_points(CORNELL)
    assert lit.points.shape == (client.describe_model(CORNELL).default.point_count, 3)
    assert lit.points.dtype == np.float32 and np.isfinite(lit.points).all()
    assert lit.status == "HIT", lit.key_point_error
    # The estimate lies in the subspace, so its own key values project back onto it: sent by the
    # client, they give the same frame with e_key ≈ 0.
    again = client.evaluate_key_points(CORNELL, keys.select(lit.points), version=keys.model_version)
    assert again.status == "HIT" and again.key_point_error < 1e-3 * lit.key_point_error + 1e-6
    np.testing.assert_allclose(again.points, lit.points, rtol=1e-4, atol=1e-5)
    # The light as a PointLight at the training intensity is the same request.
    same = client.relight(CORNELL, animspace.PointLight(tuple(INSIDE)))
    np.testing.assert_array_equal(same.points, lit.points)


def test_a_light_at_floor_level_is_flagged_and_completed_by_the_server(client):
    lit = client.relight(CORNELL, FLOOR)
    assert lit.status in ("BLEND", "MISS")
    assert not lit.full_evaluation_needed
    # Twice the training intensity: the full gather is linear in it.
    double = client.relight(CORNELL, [animspace.PointLight(tuple(FLOOR), (2.0, 2.0, 2.0))])
    if lit.status == double.status == "MISS":
        np.testing.assert_allclose(double.points, 2 * lit.points, rtol=1e-5, atol=1e-6)
    # Two lights: the indirect illumination of both is the sum of each (one gather, linear).
    a, b = client.relight(CORNELL, FLOOR), client.relight(CORNELL, [0.1, 0.03, 0.1])
    both = client.relight(CORNELL, [FLOOR, [0.1, 0.03, 0.1]])
    if a.status == b.status == both.status == "MISS":
        np.testing.assert_allclose(both.points, a.points + b.points, rtol=1e-4, atol=1e-5)


def test_a_dim_and_a_bright_light_get_the_same_verdict(client):
    # Issue #38: the tolerance is relative to each frame's own radiance. The radiance is linear in
    # the light's intensity, so the same light ten times dimmer or brighter is the same frame
    # scaled: the same verdict, the same relative errors, a scale ten times smaller or larger.
    assert client.describe_model(CORNELL).default.relative_tolerance
    for position in (INSIDE, FLOOR):
        base = client.relight(CORNELL, position)
        assert base.pose_scale > 0
        for intensity in (0.1, 10.0):
            lit = client.relight(CORNELL, [animspace.PointLight(tuple(position), (intensity,) * 3)])
            assert lit.status == base.status, (position, intensity, lit.error_estimate, base.error_estimate)
            assert lit.error_estimate == pytest.approx(base.error_estimate, rel=1e-3)
            assert lit.pose_scale == pytest.approx(intensity * base.pose_scale, rel=1e-3)
    # The arm's tolerance stays in model units (a position has no intensity).
    assert not client.describe_model("arm-pmsc").default.relative_tolerance


def test_bad_lights_are_refused_naming_the_field(client):
    with pytest.raises(ValueError, match="lights"):
        client.relight(CORNELL, [[0.1, 0.2]])
    with pytest.raises(animspace.InvalidArgument, match=r"poses\[0\]\.light_set\.lights\[0\]\.intensity"):
        client.relight(CORNELL, animspace.PointLight((0.2, 0.4, 0.2), (1.0, -1.0, 1.0)))
    with pytest.raises(animspace.InvalidArgument, match=r"poses\[0\]\.light_set"):
        client.relight("arm-pmsc", INSIDE)


def test_thumbnails_of_the_lit_room(client, tmp_path):
    total = client.render_thumbnail(CORNELL, 64, 48, lights=INSIDE)
    assert total.pose is not None and total.png[:8] == b"\x89PNG\r\n\x1a\n"
    heat = client.render_thumbnail(CORNELL, 64, 48, lights=FLOOR, show_heat_legend=True,
                                   illumination=animspace.IlluminationView(heat_from_full_gather=True))
    assert heat.heat_max_error >= 0 and heat.heat_scale_max > 0
    with pytest.raises(ValueError, match="illumination.radiance"):
        client.render_thumbnail(CORNELL, 64, 48, lights=INSIDE, illumination=animspace.IlluminationView("bright"))
