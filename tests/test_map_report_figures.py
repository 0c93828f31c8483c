"""The figures of ``skyref report`` are readable: no two labels of the Pareto plot overlap (checked
on the drawn figure, in display space, with the map's own entries and with a crowded synthetic
map), and the contact sheet shows the sky dome only, on an error scale that nothing saturates
(checked on small synthetic skies whose every pixel's error is known)."""

from __future__ import annotations

import itertools
import json
import math

import numpy as np
import pytest

from skyref.audit.map_report import contact_sheet_figure, pareto_figure, plot_contact_sheet, plot_pareto
from skyref.audit.speed_map import Entry, MapSky, cache_path, save_cached
from skyref.color import spectral_to_linear_srgb
from skyref.scene import Camera, Scene
from skyref.sky import Sky

MAP = "results/report/map.json"


def map_entries():
    with open(MAP, encoding="utf-8") as f:
        return json.load(f)["entries"]


# --- Pareto plot ---------------------------------------------------------------------------------

def drawn_labels(fig):
    """Per data axes: [(text, data point, display box of the text alone, has a leader line)]."""
    from matplotlib.text import Text

    fig.canvas.draw()
    renderer = fig.canvas.get_renderer()
    panels = []
    for ax in fig.axes:
        # Text's own extent: an Annotation's get_window_extent would include its leader line.
        panels.append([(t.get_text(), t.xy, Text.get_window_extent(t, renderer), t.arrow_patch is not None)
                       for t in ax.texts])
    return panels, renderer


def marker_centres(ax):
    return np.concatenate([ax.transData.transform(c.get_offsets()) for c in ax.collections])


def check_labels(fig, summaries):
    """Every measured entry is labelled once per panel, at its own point; no two labels overlap,
    none covers a marker or leaves its axes, and a label without a leader line is nearer its own
    marker than any other."""
    import matplotlib.pyplot as plt

    measured = [s for s in summaries if "frame_s" in s]
    panels, renderer = drawn_labels(fig)
    assert len(panels) == 2
    for ax, labels, cost in zip(fig.axes, panels, (lambda s: s["frame_s"],
                                                   lambda s: s["per_view_s"] + 1920 * 1080 * s["lookup_s"])):
        assert sorted(text for text, *_ in labels) == sorted(f"{s['method']} {s['label']}" for s in measured)
        points = {f"{s['method']} {s['label']}": (cost(s), 100 * s["sky_rms_median"]) for s in measured}
        for text, xy, _, _ in labels:
            assert xy == pytest.approx(points[text], rel=1e-12)
        for (a, _, box_a, _), (b, _, box_b, _) in itertools.combinations(labels, 2):
            assert not box_a.overlaps(box_b), (a, b)
        frame = ax.get_window_extent(renderer)
        centres = marker_centres(ax)
        radius = renderer.points_to_pixels(math.sqrt(ax.collections[0].get_sizes()[0])) / 2
        for text, xy, box, leader in labels:
            assert frame.x0 <= box.x0 and box.x1 <= frame.x1 and frame.y0 <= box.y0 and box.y1 <= frame.y1, text
            for x, y in centres:
                assert not box.overlaps(type(box).from_bounds(x - radius, y - radius, 2 * radius, 2 * radius)), text
            if not leader:
                own = ax.transData.transform(xy)
                gap = lambda c: math.hypot(max(box.x0 - c[0], 0, c[0] - box.x1), max(box.y0 - c[1], 0, c[1] - box.y1))  # noqa: E731
                others = [c for c in centres if np.hypot(*(c - own)) > 2 * radius]   # markers not on top of its own
                assert all(gap(c) > gap(own) for c in others), text
    plt.close(fig)


def test_pareto_labels_of_the_map_do_not_overlap():
    entries = map_entries()
    assert len([s for s in entries if "frame_s" in s]) >= 15
    check_labels(pareto_figure(entries), entries)


def summary(method, label, frame_s, rms, family="LUT"):
    return {"entry": f"{method} {label}", "family": family, "method": method, "label": label, "frame_s": frame_s,
            "precompute_s": 0.0, "per_view_s": frame_s / 2, "lookup_s": frame_s / 2 / (1920 * 1080),
            "sky_rms_median": rms}


def test_pareto_labels_of_a_crowded_map_do_not_overlap():
    """Six long labels on one point, a tight cluster around it and points on the axes' corners."""
    rng = np.random.default_rng(3)
    summaries = [summary("coincident", f"setting {i} (32x128x32x8, {i} orders)", 10.0, 0.05) for i in range(6)]
    summaries += [summary("cluster", f"variant {i}", 10.0 * 1.15 ** rng.normal(), 0.05 * 1.1 ** rng.normal(), "analytic")
                  for i in range(8)]
    summaries += [summary("corner", f"{name} corner", x, y, "path tracer")
                  for name, x, y in (("low", 0.01, 0.001), ("high", 1e4, 3.0), ("mixed", 0.01, 3.0), ("other", 1e4, 0.001))]
    summaries.append({"entry": "refused everywhere", "family": "LUT", "method": "refused", "label": "everywhere"})
    check_labels(pareto_figure(summaries), summaries)


def test_pareto_png_is_written(tmp_path):
    from PIL import Image

    path = tmp_path / "pareto.png"
    plot_pareto(map_entries()[:5], str(path))
    with Image.open(path) as image:
        assert image.size == (14 * 120, int(6.5 * 120))


# --- contact sheet -------------------------------------------------------------------------------

HEIGHT, WIDTH = 16, 32
SKY_ROWS = HEIGHT // 2        # rows 0..7: pixel-centre zenith below 90°; rows 8..15: ground
GROUND_ERROR = 1e4            # a method's error on the ground: must neither show nor stretch the scale


def synthetic_truth(path, blue):
    """A sky of 3 wavelengths: bluish above the horizon (radiance rising with ``blue``), reddish
    below; written as the ground-truth EXR the sheet reads."""
    scene = Scene(camera=Camera("equirectangular", width=WIDTH, height=HEIGHT), wavelengths=(450.0, 550.0, 650.0),
                  name="synthetic")
    radiance = np.empty((HEIGHT, WIDTH, 3), np.float32)
    zenith = (np.arange(HEIGHT) + 0.5) / HEIGHT * np.pi
    radiance[:SKY_ROWS] = (np.array([blue, 0.5, 0.2]) * (1.0 + 0.5 * np.sin(zenith[:SKY_ROWS])[:, None, None]))
    radiance[SKY_ROWS:] = np.array([0.05, 0.1, 0.3])
    sky = Sky(radiance=radiance, standard_error=0.01 * radiance, wavelengths_nm=scene.wavelengths_nm,
              directions=np.zeros((HEIGHT, WIDTH, 3)), scene=scene)
    sky.save(path)
    return spectral_to_linear_srgb(radiance.astype(np.float64), scene.wavelengths_nm)


def sky_errors(seed, smallest, largest):
    """Relative errors of a method per pixel: over the sky, magnitudes log-spaced from
    ``smallest`` to ``largest`` in random order, half of them negative (a factor as much too dark:
    -m / (1 + m)); GROUND_ERROR on the ground."""
    rng = np.random.default_rng(seed)
    magnitude = rng.permutation(np.geomspace(smallest, largest, SKY_ROWS * WIDTH)).reshape(SKY_ROWS, WIDTH)
    sign = rng.permutation(np.arange(SKY_ROWS * WIDTH) % 2).reshape(SKY_ROWS, WIDTH)
    errors = np.full((HEIGHT, WIDTH), GROUND_ERROR)
    errors[:SKY_ROWS] = np.where(sign, magnitude, -magnitude / (1.0 + magnitude))
    return errors


@pytest.fixture(scope="module")
def sheet(tmp_path_factory):
    """Two kinds of sky (a third sky of a kind already shown is skipped), a method with known
    errors (0.1%–300% on the clear sky, 0.1%–1% on the hazy one) and a method that refused."""
    directory = tmp_path_factory.mktemp("sheet")
    skies = [(MapSky("clear, sun 30°", "clear", 0, 0.0, 30.0), str(directory / "clear.exr")),
             (MapSky("hazy, sun 30°", "hazy", 1, 0.0, 30.0), str(directory / "hazy.exr")),
             (MapSky("clear, sun 60°", "clear", 0, 0.0, 60.0), str(directory / "clear60.exr"))]
    method, refusing = Entry("elek2009", "LUT", "paper"), Entry("oneil2005", "analytic", "default")
    cache = str(directory / "cache")
    errors = {"clear": sky_errors(1, 1e-3, 3.0), "hazy": sky_errors(2, 1e-3, 1e-2)}
    for i, (sky, path) in enumerate(skies):
        truth_rgb = synthetic_truth(path, blue=1.0 + i)
        if sky.kind in errors:
            save_cached(cache_path(cache, method, sky, path), {},
                        (truth_rgb * (1.0 + errors[sky.kind])[..., None]).astype(np.float32))
        save_cached(cache_path(cache, refusing, sky, path), {"refused": "outside its range"}, None)
    return [method, refusing], skies, cache, errors


def expected_dome(values, size):
    """The sky dome of an equirectangular (H, W) map by the conventions of skyref.projection's
    docstrings (upward equidistant fisheye: radius 1 at the horizon, north up, east left; map
    columns: azimuth clockwise from north, rows: zenith 0–180°), nearest pixel; NaN off the dome
    and on the ground. Also returns where the answer is unambiguous (no pixel edge within 1%)."""
    centre = (np.arange(size) + 0.5) / size
    b, a = 1.0 - 2.0 * centre[:, None], 2.0 * centre[None, :] - 1.0       # image up, image right
    r = np.hypot(a, b)
    row = np.degrees(r * np.pi / 2) / 180.0 * HEIGHT
    column = np.mod(np.degrees(np.arctan2(-a, b)), 360.0) / 360.0 * WIDTH
    clear = (np.abs(row - np.round(row)) > 0.01) & (np.abs(column - np.round(column)) > 0.01)
    i, j = np.minimum(row.astype(int), HEIGHT - 1), np.minimum(column.astype(int), WIDTH - 1)
    dome = np.where((r <= 1.0) & (i < SKY_ROWS), values[i, j], np.nan)
    return dome, clear


def test_contact_sheet_shows_the_sky_dome_only(sheet):
    import matplotlib.pyplot as plt

    entries, skies, cache, errors = sheet
    fig = contact_sheet_figure(entries, skies, cache)
    axes = np.array(fig.axes[:-1]).reshape(3, 4)            # rows: truth, elek2009, oneil2005; the colour bar last
    assert [axes[0, 0].get_title(), axes[0, 2].get_title()] == ["clear, sun 30°", "hazy, sun 30°"]
    for j, kind in enumerate(("clear", "hazy")):
        shown = np.ma.filled(axes[1, 2 * j + 1].images[0].get_array().astype(float), np.nan)
        dome, clear = expected_dome(errors[kind], shown.shape[0])
        assert shown.shape[0] == shown.shape[1] >= 2 * SKY_ROWS
        assert np.array_equal(np.isnan(shown)[clear], np.isnan(dome)[clear])
        # The same pixel's error (each is unique), up to the float32 of the cached image.
        np.testing.assert_allclose(shown[clear & ~np.isnan(dome)], dome[clear & ~np.isnan(dome)],
                                   rtol=1e-5, atol=1e-6)
        assert np.nanmax(np.abs(shown)) < GROUND_ERROR
        # About pi/4 of the square is the dome.
        assert np.mean(~np.isnan(shown)) == pytest.approx(math.pi / 4, abs=0.04)
        for i in (0, 1):
            image = axes[i, 2 * j].images[0].get_array()
            visible = image[..., 3] > 0
            assert np.array_equal(visible, ~np.isnan(shown))      # the same dome, transparent around it
            assert np.all(image[..., 2][visible] > image[..., 0][visible])   # blue sky, never the red ground
    assert not axes[2, 0].images and "refused" in axes[2, 0].texts[0].get_text()
    plt.close(fig)


def test_contact_sheet_error_scale_does_not_saturate(sheet):
    import matplotlib.pyplot as plt

    entries, skies, cache, _ = sheet
    fig = contact_sheet_figure(entries, skies, cache)
    images = [ax.images[0] for ax in fig.axes[:-1] if ax.images and ax.images[0].get_array().ndim == 2]
    assert len(images) == 2
    norm, cmap = images[0].norm, images[0].get_cmap()
    for image in images:
        values = np.ma.filled(image.get_array().astype(float), np.nan)
        scaled = norm(values[np.isfinite(values)])
        assert scaled.min() >= 0.0 and scaled.max() <= 1.0              # nothing beyond the ends
    # The scale ends at the largest error shown (300%), not at the ground's and not before.
    assert norm.vmax == pytest.approx(3.0, rel=0.02) and norm.vmin == pytest.approx(-3.0, rel=0.02)
    colours = cmap(norm(np.array([1e-3, 1e-2, 1e-1, 1.0, 3.0])))[:, :3]
    for a, b in itertools.combinations(colours, 2):
        assert np.abs(a - b).max() > 0.04                             # each decade its own colour
    assert np.all(norm(np.array([1e-3, 0.1, 2.0])) > 0.5) and np.all(norm(np.array([-1e-3, -0.1, -0.75])) < 0.5)
    label = fig.axes[-1].get_ylabel()
    assert "300%" in label and "1%" in label
    plt.close(fig)


def test_contact_sheet_png_is_written(sheet, tmp_path):
    from PIL import Image

    entries, skies, cache, _ = sheet
    path = tmp_path / "contact_sheet.png"
    plot_contact_sheet(entries, skies, cache, str(path))
    with Image.open(path) as image:
        assert image.size[0] > 400 and image.size[1] > 200
