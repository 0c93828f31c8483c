"""Views that see the same sky (skyref.symmetry): which pixels pair up, that a render tracing one of
each pair agrees with one tracing every pixel (Stokes vectors too: U and V turned over in a mirror
image), and that statistics over pixels add the noise of a shared estimate coherently
(skyref.audit.metrics)."""

import numpy as np
import pytest

from skyref.audit.metrics import _statistics, shared_estimates
from skyref.errors import ParameterError
from skyref.render import render_sky, render_to_error, rendered_pixels
from skyref.scene import Camera, Observer, RenderSettings, Scene, SceneObject, Sun
from skyref.symmetry import view_groups


def scene_with(sun, width=64, height=32, altitude_m=100.0, **render):
    """A scene seen from ``altitude_m`` (default 100 m: views below the horizon meet the ground
    at different points, paired by the mirror alone; at 0 they all meet it at the observer's feet)."""
    settings = {"pixel_sampling": "centre", **render}
    return Scene(sun=sun, observer=Observer(altitude_m), camera=Camera(width=width, height=height),
                 wavelengths="rgb", render=RenderSettings(**settings))


def pixel_angles(width, height):
    """(zenith, azimuth) in degrees of each pixel centre of an equirectangular camera, flat, from
    its definition (rows from the zenith, columns from azimuth 0): independent of skyref.projection."""
    zenith = np.repeat((np.arange(height) + 0.5) * 180.0 / height, width)
    azimuth = np.tile((np.arange(width) + 0.5) * 360.0 / width, height)
    return zenith, azimuth


@pytest.mark.parametrize("sun_azimuth", [180.0, 182.8125])
def test_each_pixel_shares_the_estimate_of_its_mirror_image_across_the_sun_vertical(sun_azimuth):
    """Sun at azimuth 180 (on a column edge of 64 columns of 5.625 deg): every column has a
    partner; at 182.8125 (a column centre, the Hosek training grid's), the sun's column and the
    one opposite are their own mirror images: 33 views per row instead of 64."""
    scene = scene_with(Sun(60.0, sun_azimuth))
    pixels = rendered_pixels(scene)
    groups, mirrored = view_groups(scene, pixels)
    zenith, azimuth = pixel_angles(64, 32)
    mirror = np.mod(2.0 * sun_azimuth - azimuth, 360.0)
    # the pixel whose estimate each one takes has its zenith and its own or its mirror azimuth,
    # and is said to be mirrored exactly where it is the mirror azimuth (the sun's column and the
    # one opposite are their own mirror images, which is no mirroring)
    assert np.array_equal(zenith[groups], zenith)
    own = np.isclose(azimuth[groups], azimuth)
    assert (own | np.isclose(azimuth[groups], mirror)).all()
    assert np.array_equal(mirrored, ~own)
    expected = 32 * 32 if sun_azimuth == 180.0 else 32 * 33
    assert np.unique(groups).size == expected
    assert mirrored.sum() == pixels.size - expected


def test_with_the_sun_at_the_zenith_a_row_is_one_view():
    """A rotation about the vertical: every copy keeps its Stokes vector (none is mirrored)."""
    scene = scene_with(Sun(0.0, 180.0))
    groups, mirrored = view_groups(scene, rendered_pixels(scene))
    assert np.array_equal(groups, np.repeat(np.arange(32) * 64, 64))
    assert not mirrored.any()


@pytest.mark.parametrize("sun", [Sun(60.0, 180.0), Sun(0.0, 180.0), Sun(60.0, 10.0)], ids=["mirror", "zenith sun", "no mirror"])
def test_an_observer_on_the_ground_sees_one_ground_below_the_horizon(sun):
    """At altitude 0 every view below the horizon (rows 16-31 of 32) takes the estimate of the
    first of them, unmirrored (the ground is unpolarized); the sky's views group as before."""
    on_ground, above = scene_with(sun, altitude_m=0.0), scene_with(sun)
    pixels = rendered_pixels(on_ground)
    groups, mirrored = view_groups(on_ground, pixels)
    zenith, _ = pixel_angles(64, 32)
    below = zenith > 90.0
    assert np.all(groups[below] == 16 * 64) and not mirrored[below].any()
    sky_groups, sky_mirrored = view_groups(above, pixels)
    assert np.array_equal(groups[~below], sky_groups[~below]) and np.array_equal(mirrored[~below], sky_mirrored[~below])
    assert np.unique(groups).size == np.unique(sky_groups[~below]).size + 1


@pytest.mark.parametrize("case", ["sun off the columns' symmetry", "area sampling", "object"])
def test_no_view_is_shared_where_the_symmetry_does_not_hold(case):
    scene = {"sun off the columns' symmetry": scene_with(Sun(60.0, 10.0)),
             "area sampling": scene_with(Sun(60.0, 180.0), pixel_sampling="area"),
             "object": scene_with(Sun(60.0, 180.0)).replace(objects=(SceneObject("sphere", scale_m=(10.0, 10.0, 10.0),
                                                                                    translate_m=(50.0, 0.0, 20.0)),))}[case]
    pixels = rendered_pixels(scene)
    groups, mirrored = view_groups(scene, pixels)
    assert np.array_equal(groups, np.arange(pixels.size)) and not mirrored.any()


@pytest.mark.parametrize("sun,altitude_m,views", [(Sun(60.0, 180.0), 100.0, 64), (Sun(0.0, 180.0), 100.0, 8),
                                                   (Sun(60.0, 10.0), 0.0, 65)],
                         ids=["mirror", "zenith sun", "ground at the feet"])
def test_a_symmetric_render_agrees_with_one_that_traces_every_pixel(mi, sun, altitude_m, views):
    """Delta tracking (the mapping is the subject, not the estimator), 16x8 pixels: the copies
    are bit-identical, and every pixel agrees with an independent render of every pixel within
    the standard errors. A wrong partner (a pixel towards the sun for one away from it) differs
    by tens of percent, hundreds of standard errors at these ~1-3% errors; seen from 100 m, the
    ground below differs from view to view by its air in between."""
    scene = scene_with(sun, 16, 8, altitude_m=altitude_m, estimator="delta_tracking")
    symmetric = render_sky(scene, spp=4096, passes=16, seed=7)
    everything = render_sky(scene, spp=4096, passes=16, seed=8, symmetry=False)
    assert symmetric.metadata["views_traced"] == views
    assert everything.metadata["views_traced"] == 128
    flat = symmetric.radiance.reshape(128, -1)
    groups, _ = view_groups(scene, np.arange(128))
    assert np.array_equal(flat, flat[groups])
    z = (symmetric.radiance - everything.radiance) / np.hypot(symmetric.standard_error, everything.standard_error)
    assert np.all(np.isfinite(z)) and np.max(np.abs(z)) < 4.5, np.max(np.abs(z))
    assert 0.6 < np.mean(z ** 2) < 1.5, np.mean(z ** 2)


def test_a_symmetric_polarized_render_turns_u_and_v_over_in_a_mirror_image(mi):
    """The default atmosphere (Rayleigh, a non-polarizing aerosol, a Lambertian ground: V = 0),
    sun at zenith 60, 16x8 pixels: off the sun's vertical plane U is
    tens of percent of I with opposite signs on its two sides. A copy of a mirror image has its
    view's I and Q and -U bit for bit, and every component agrees with an independent render of
    every pixel within the standard errors: a copy that kept U would be off by 2|U|, many
    standard errors. A 1% bias of I (measured, 16384 samples): mean z^2 1.72 / 1.36 for +1% / -1%,
    and sqrt(n) x mean z of I 12.0 / -9.6 against 1.2 unbiased (I is positive, so a bias moves
    every z one way; Q and U take both signs)."""
    scene = scene_with(Sun(60.0, 180.0), 16, 8, estimator="delta_tracking", polarized=True)
    symmetric = render_sky(scene, spp=16384, passes=16, seed=7)
    everything = render_sky(scene, spp=16384, passes=16, seed=8, symmetry=False)
    assert symmetric.metadata["views_traced"] == 64
    groups, mirrored = view_groups(scene, np.arange(128))
    stokes = symmetric.stokes.reshape(128, 4, -1)
    assert np.array_equal(stokes[:, :2], stokes[groups, :2])
    assert np.array_equal(stokes[mirrored, 2:], -stokes[groups[mirrored], 2:])
    sky = everything.directions[..., 2] > 0.0                  # below: the ground, unpolarized (Q = U = 0 exactly)
    u = everything.stokes[sky][:, 2]
    assert np.max(np.abs(u) / everything.radiance[sky]) > 0.1  # U is there to be mirrored
    for component in range(3):                                  # I, Q, U (V is 0 in both)
        z = ((symmetric.stokes[sky][:, component] - everything.stokes[sky][:, component])
             / np.hypot(symmetric.stokes_error[sky][:, component], everything.stokes_error[sky][:, component]))
        assert np.all(np.isfinite(z)) and np.max(np.abs(z)) < 4.5, (component, np.max(np.abs(z)))
        assert 0.6 < np.mean(z ** 2) < 1.5, (component, np.mean(z ** 2))
        if component == 0:
            assert abs(np.mean(z)) * np.sqrt(z.size) < 4.0, np.mean(z)


def test_an_adaptive_render_counts_samples_and_targets_per_pixel(mi):
    """render_to_error traces one view of each pair: the metadata's samples per pixel, their
    range and the share at the target are those of the pixels (each copy has its view's), the
    views traced half of them."""
    scene = scene_with(Sun(40.0, 180.0), 8, 6, passes=16, estimator="delta_tracking")
    sky = render_to_error(scene, 0.02, seeds=[11, 12, 13], max_spp=4096)
    assert sky.metadata["views_traced"] == 24
    flat = sky.radiance.reshape(48, -1)
    assert np.array_equal(flat, flat[view_groups(scene, np.arange(48))[0]])
    worst = np.max(sky.standard_error / sky.radiance, axis=-1)
    assert sky.metadata["pixels_at_target"] == pytest.approx(np.mean(worst <= 0.02))


def test_a_view_traced_for_many_pixels_may_take_their_samples(mi):
    """max_spp bounds what each pixel costs: a view traced once for n pixels may take n x max_spp.
    Observer on the ground, 8 x 4 pixels, the sun on a column edge: the sky's 16 pixels are 8
    mirror pairs, the ground's 16 one view at the observer's feet. With a target out of reach the
    pairs end at 2 x 64 samples and the feet's view above that, within 16 x 64."""
    scene = scene_with(Sun(40.0, 180.0), 8, 4, altitude_m=0.0, passes=16, estimator="delta_tracking")
    sky = render_to_error(scene, 1e-5, seeds=[11, 12, 13, 14], max_spp=64)
    assert sky.metadata["views_traced"] == 9
    low, high = sky.metadata["spp_range"]
    assert low == 2 * 64 and 2 * 64 < high <= 16 * 64, (low, high)


def test_an_adaptive_polarized_render_turns_u_and_v_over_in_a_mirror_image(mi):
    scene = scene_with(Sun(40.0, 180.0), 8, 6, passes=16, estimator="delta_tracking", polarized=True)
    sky = render_to_error(scene, 0.05, seeds=[11, 12], max_spp=1024)
    assert sky.metadata["views_traced"] == 24
    groups, mirrored = view_groups(scene, np.arange(48))
    stokes, error = sky.stokes.reshape(48, 4, -1), sky.stokes_error.reshape(48, 4, -1)
    assert mirrored.sum() == 24
    assert np.array_equal(stokes[:, :2], stokes[groups, :2]) and np.array_equal(error, error[groups])
    assert np.array_equal(stokes[mirrored, 2:], -stokes[groups[mirrored], 2:])
    assert np.abs(stokes[mirrored, 2]).max() > 0.0


def test_the_keyword_refuses_a_bad_value_before_any_work():
    scene = scene_with(Sun(60.0, 180.0), 8, 4)
    with pytest.raises(ParameterError, match=r"symmetry = 'no': not a boolean"):
        render_sky(scene, symmetry="no")
    with pytest.raises(ParameterError, match=r"symmetry = 1: not a boolean"):
        render_to_error(scene, 0.01, seeds=[1], max_spp=64, symmetry=1)


def test_shared_estimates_are_told_by_equal_values_in_every_channel():
    truth = np.array([[1.0, 2.0], [1.0, 2.0], [1.0, 2.5], [0.0, 0.0]])
    error = np.array([[0.1, 0.1], [0.1, 0.1], [0.1, 0.1], [0.0, 0.0]])
    labels = shared_estimates(truth, error)
    assert labels[0] == labels[1] and len({labels[0], labels[2], labels[3]}) == 3


def test_the_noise_of_a_region_adds_coherently_over_a_shared_estimate():
    """The noise _statistics states for the mean and the noise-corrected mean square against the
    spread of those statistics over simulated truths in which pairs of pixels carry one noise
    draw: copies double the variance of the mean, which the independent formula would miss."""
    rng = np.random.default_rng(3)
    pixels = 400
    error_true = rng.normal(0.05, 0.03, pixels)
    noise = rng.uniform(0.01, 0.03, pixels // 2).repeat(2)               # pairs share a noise level
    estimates = np.arange(pixels) // 2
    draws = rng.standard_normal((4000, pixels // 2)).repeat(2, axis=1)  # and a noise draw
    observed = error_true + noise * draws
    means, squares = observed.mean(axis=1), np.mean(observed ** 2, axis=1)
    stated = _statistics(observed[0], noise, estimates)
    independent = _statistics(observed[0], noise)
    assert stated["noise_mean"] == pytest.approx(means.std(), rel=0.05)
    assert independent["noise_mean"] == pytest.approx(means.std() / np.sqrt(2.0), rel=0.05)
    # the RMS's noise is that of the mean square over 2 rms (the delta method)
    rms_noise = squares.std() / (2.0 * np.sqrt(max(stated["rms"] ** 2, 1e-12)))
    assert stated["noise_rms"] == pytest.approx(rms_noise, rel=0.15)
