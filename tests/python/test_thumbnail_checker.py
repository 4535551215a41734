"""render_thumbnail(..., texture_checker=True) (issue #37): the demo's arm-smooth, which stores a
texture atlas, drawn with its atlas as a checker. With Lambert shading a pixel is albedo × light,
so the checker's pixel over the plain surface's pixel is the checker colour over the plain albedo
(scene.h: 0.92 and 0.20 against 0.80) whatever the light: every lit pixel is one of the two
ratios, both appear, and the silhouette is the plain one's. Refusals name the field and the model.
"""
import io

import numpy as np
import pytest

import animspace

MODEL = "arm-smooth"  # the demo model with an atlas
PLAIN = "arm-animspace"  # one without


def _pixels(thumbnail):
    Image = pytest.importorskip("PIL.Image")
    return np.asarray(Image.open(io.BytesIO(thumbnail.png)).convert("RGBA")).astype(np.float64)


def test_the_checker_is_the_plain_surface_times_one_of_two_albedos(client):
    common = dict(shading="lambert", samples=1, background_rgba=[0, 0, 1, 1])
    plain = _pixels(client.render_thumbnail(MODEL, 128, 96, **common))
    checker = _pixels(client.render_thumbnail(MODEL, 128, 96, texture_checker=True, checker_squares=8, **common))
    background = (plain[..., 0] == 0) & (plain[..., 1] == 0) & (plain[..., 2] == 255)
    np.testing.assert_array_equal(background, (checker[..., 0] == 0) & (checker[..., 1] == 0) & (checker[..., 2] == 255))
    lit = ~background & (plain[..., 0] >= 40)
    assert lit.sum() > 500
    ratio = checker[..., 0][lit] / plain[..., 0][lit]
    tolerance = 1.5 / plain[..., 0][lit] + 0.01
    even = np.abs(ratio - 0.92 / 0.80) <= tolerance
    odd = np.abs(ratio - 0.20 / 0.80) <= tolerance
    assert np.all(even | odd), ratio[~(even | odd)][:10]
    assert even.sum() > lit.sum() / 5 and odd.sum() > lit.sum() / 5


def test_a_checker_without_an_atlas_or_with_bad_squares_is_refused(client):
    with pytest.raises(animspace.FailedPrecondition) as refused:
        client.render_thumbnail(PLAIN, 32, 32, texture_checker=True)
    assert f"texture_checker: model '{PLAIN}' version 1 stores no texture atlas" in refused.value.message
    assert "`animspace atlas" in refused.value.message
    with pytest.raises(animspace.InvalidArgument, match="checker_squares: expected > 0 .* got -2"):
        client.render_thumbnail(MODEL, 32, 32, texture_checker=True, checker_squares=-2)
    with pytest.raises(ValueError, match="checker_squares: expected an integer"):
        client.render_thumbnail(MODEL, 32, 32, texture_checker=True, checker_squares=2.5)
