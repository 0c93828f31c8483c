"""The Mitsuba equirectangular and fisheye sensors: rays against skyref.projection, renders of a
constant environment against the constant."""

import numpy as np
import pytest

from skyref import _llvm, projection
from skyref.scene import Camera
from tests.variants import RGB, SPECTRAL

_llvm.configure_libllvm()
mi = pytest.importorskip("mitsuba")

VARIANTS = [RGB, SPECTRAL]
ORIGIN = [10.0, -20.0, 30.0]


@pytest.fixture(params=VARIANTS)
def variant(request):
    mi.set_variant(request.param)
    from skyref.plugins.sensors import register_sensors

    register_sensors()
    register_sensors()  # idempotent
    yield request.param
    mi.set_variant(RGB)  # the variant every other test module expects


def sensor_dict(camera, spp=4, **film):
    to_world = projection.camera_to_world(camera)
    to_world[:3, 3] = ORIGIN
    sensor = {"type": camera.type, "to_world": mi.ScalarTransform4f(to_world),
              "film": {"type": "hdrfilm", "width": camera.width, "height": camera.height,
                       "rfilter": {"type": "box"}, **film},
              "sampler": {"type": "independent", "sample_count": spp}}
    if camera.type == "fisheye":
        sensor["fov"] = camera.fov_deg
    elif camera.type == "perspective":
        sensor["fov"], sensor["fov_axis"] = camera.fov_deg, "x"
    return sensor


def pixel_centre_rays(sensor, width, height):
    j, i = np.meshgrid(np.arange(width), np.arange(height))
    u = ((j + 0.5) / width).ravel()
    v = ((i + 0.5) / height).ravel()
    ray, weight = sensor.sample_ray(time=0.0, sample1=mi.Float(np.linspace(0.01, 0.99, u.size)),
                                    sample2=mi.Point2f(u, v), sample3=mi.Point2f(0.5, 0.5), active=True)
    direction = np.array(ray.d).T.reshape(height, width, 3)
    origin = np.array(ray.o).T.reshape(-1, 3)                      # may be one broadcast origin
    weight = np.array(weight)                                      # (channels, 1 or n)
    weight = np.broadcast_to(weight, (weight.shape[0], u.size)).reshape(-1, height, width)
    return direction, origin, weight


CAMERAS = [Camera("equirectangular", width=16, height=8),
           Camera("fisheye", width=15, height=15, fov_deg=180.0),
           Camera("fisheye", width=12, height=10, fov_deg=150.0, view_zenith_deg=60.0, view_azimuth_deg=120.0),
           Camera("fisheye", width=9, height=9, fov_deg=360.0, view_zenith_deg=180.0)]


@pytest.mark.parametrize("camera", CAMERAS, ids=lambda c: f"{c.type}-{c.fov_deg:g}-{c.view_zenith_deg:g}")
def test_rays_match_pixel_directions(variant, camera):
    sensor = mi.load_dict(sensor_dict(camera))
    direction, origin, weight = pixel_centre_rays(sensor, camera.width, camera.height)
    expected = projection.pixel_directions(camera)
    inside = ~np.isnan(expected[..., 0])
    assert np.allclose(direction[inside], expected[inside], atol=2e-6)
    assert np.allclose(origin, ORIGIN)
    assert np.all(weight[:, ~inside] == 0.0)
    if variant.endswith("rgb"):
        assert np.all(weight[:, inside] == 1.0)
    else:
        assert np.all(weight[:, inside] > 0.0)


def test_stock_perspective_agrees_with_camera_to_world(variant):
    """A stock Mitsuba perspective sensor given camera_to_world sees pixel_directions."""
    camera = Camera("perspective", width=12, height=8, fov_deg=70.0, view_zenith_deg=75.0, view_azimuth_deg=300.0)
    sensor = mi.load_dict(sensor_dict(camera))
    direction, _, _ = pixel_centre_rays(sensor, camera.width, camera.height)
    assert np.allclose(direction, projection.pixel_directions(camera), atol=2e-6)


def test_crop_window_maps_to_full_film(variant):
    camera = Camera("equirectangular", width=16, height=8)
    sensor = mi.load_dict(sensor_dict(camera, crop_offset_x=4, crop_offset_y=2, crop_width=8, crop_height=4))
    direction, _, _ = pixel_centre_rays(sensor, 8, 4)
    assert np.allclose(direction, projection.pixel_directions(camera)[2:6, 4:12], atol=2e-6)


def render_constant(variant, camera, value, spp):
    radiance = {"type": "rgb", "value": [value] * 3} if variant.endswith("rgb") else value
    scene = mi.load_dict({"type": "scene", "integrator": {"type": "path"},
                          "sensor": sensor_dict(camera, spp=spp),
                          "environment": {"type": "constant", "radiance": radiance}})
    return np.array(mi.render(scene, seed=1))[..., :3]


@pytest.mark.parametrize("camera", CAMERAS[:2], ids=lambda c: c.type)
def test_render_constant_environment(variant, camera):
    value = 0.5
    spp = 16 if variant.endswith("rgb") else 1024
    image = render_constant(variant, camera, value, spp)
    assert image.shape == (camera.height, camera.width, 3)
    # Pixels wholly inside the circle see the constant; pixels wholly outside see nothing.
    j, i = np.meshgrid(np.arange(camera.width), np.arange(camera.height))
    dx = np.maximum(np.abs(2 * (j + 0.5) / camera.width - 1) - 1 / camera.width, 0)
    dy = np.maximum(np.abs(2 * (i + 0.5) / camera.height - 1) - 1 / camera.height, 0)
    near = np.hypot(dx, dy)                                        # nearest point of each pixel
    far = np.hypot(np.abs(2 * (j + 0.5) / camera.width - 1) + 1 / camera.width,
                   np.abs(2 * (i + 0.5) / camera.height - 1) + 1 / camera.height)
    inside = np.ones_like(near, bool) if camera.type == "equirectangular" else far <= 1
    outside = np.zeros_like(near, bool) if camera.type == "equirectangular" else near > 1
    if camera.type == "fisheye":
        assert inside.sum() > 100 and outside.sum() > 8
    assert np.all(image[outside] == 0.0)
    if variant.endswith("rgb"):
        assert np.allclose(image[inside], value, rtol=1e-6)
    else:
        # Wavelength sampling makes each pixel noisy (blue's relative std ~ 2% at 1024 spp);
        # the image mean is tight.
        assert np.allclose(image[inside], value, rtol=0.12)
        assert np.allclose(image[inside].mean(axis=0), value, rtol=0.01)


def test_fisheye_rejects_bad_fov(variant):
    with pytest.raises(Exception, match="fov"):
        mi.load_dict({"type": "fisheye", "fov": 400.0})


def test_bbox_is_the_origin(variant):
    sensor = mi.load_dict(sensor_dict(Camera("fisheye", width=4, height=4)))
    bbox = sensor.bbox()
    assert np.allclose(np.array(bbox.min), ORIGIN) and np.allclose(np.array(bbox.max), ORIGIN)
