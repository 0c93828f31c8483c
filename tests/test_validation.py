"""Every invalid parameter is rejected up front with a ParameterError that names it."""

import math
import re

import pytest

import skyref.atmosphere as sa
from skyref.atmosphere import (Absorber, Aerosol, Atmosphere, CornetteShanks, ExponentialProfile,
                               HenyeyGreenstein, PiecewiseLinearProfile, Rayleigh, TabulatedProfile,
                               TabulatedSpectrum)
from skyref.errors import ParameterError
from skyref.scene import Camera, Observer, RenderSettings, Scene, Sun, load_scene


def raises_named(name):
    """pytest.raises for a ParameterError whose message starts with ``name = ``."""
    return pytest.raises(ParameterError, match="^" + re.escape(name) + " = ")


def scene_dict(**tables):
    data = {"atmosphere": {"preset": "bruneton2017"}, "spectral": {"wavelengths": "rgb"}}
    data.update(tables)
    return data


# --- atmosphere geometry --------------------------------------------------------------------

def test_top_below_bottom():
    with raises_named("top_radius_m"):
        Atmosphere(bottom_radius_m=6_420_000.0, top_radius_m=6_360_000.0)


def test_top_equal_bottom():
    with raises_named("top_radius_m"):
        Atmosphere(bottom_radius_m=6_360_000.0, top_radius_m=6_360_000.0)


@pytest.mark.parametrize("value", [0.0, -1.0, 1e12, math.nan, math.inf, "6360 km", True])
def test_bad_bottom_radius(value):
    with raises_named("bottom_radius_m"):
        Atmosphere(bottom_radius_m=value, top_radius_m=7e6)


def test_error_carries_name_value_and_range():
    with pytest.raises(ParameterError) as info:
        Atmosphere(bottom_radius_m=6e6, top_radius_m=5e6)
    err = info.value
    assert err.name == "top_radius_m" and err.value == 5e6
    assert "valid" in str(err) and "6e+06" in err.valid


# --- profiles ---------------------------------------------------------------------------------

@pytest.mark.parametrize("value", [-8000.0, 0.0, math.nan, math.inf, -math.inf])
def test_bad_scale_height(value):
    with raises_named("scale_height_m"):
        ExponentialProfile(value)


@pytest.mark.parametrize("altitudes", [(0.0, 0.0, 1.0), (0.0, 2.0, 1.0), (5.0, 4.0)])
def test_non_increasing_altitudes(altitudes):
    with raises_named("altitudes_m"):
        PiecewiseLinearProfile(altitudes, (1.0,) * len(altitudes))
    with raises_named("altitudes_m"):
        TabulatedProfile(altitudes, (1.0,) * len(altitudes))


def test_negative_density():
    with raises_named("densities[1]"):
        PiecewiseLinearProfile((0.0, 1.0, 2.0), (1.0, -0.5, 0.0))
    with raises_named("densities[0]"):
        TabulatedProfile((0.0, 1.0), (-1e-9, 0.0))


@pytest.mark.parametrize("bad", [math.nan, math.inf])
def test_non_finite_profile_entries(bad):
    with raises_named("altitudes_m[1]"):
        PiecewiseLinearProfile((0.0, bad, 2.0), (1.0, 1.0, 1.0))
    with raises_named("densities[2]"):
        PiecewiseLinearProfile((0.0, 1.0, 2.0), (1.0, 1.0, bad))


def test_too_short_profile():
    with raises_named("altitudes_m"):
        PiecewiseLinearProfile((0.0,), (1.0,))


def test_unknown_profile_type_and_key():
    with raises_named("profile.type"):
        Atmosphere.from_dict({"constituents": {"rayleigh": {"kind": "rayleigh",
                                                            "profile": {"type": "gaussian"}}}})
    with raises_named("profile.scale_hieght_m"):
        Atmosphere.from_dict({"constituents": {"rayleigh": {
            "kind": "rayleigh", "profile": {"type": "exponential", "scale_hieght_m": 8000.0}}}})
    with raises_named("profile.densities"):
        Atmosphere.from_dict({"constituents": {"rayleigh": {
            "kind": "rayleigh", "profile": {"type": "piecewise_linear", "altitudes_m": [0.0, 1.0]}}}})


# --- phase functions, constituents -----------------------------------------------------------

@pytest.mark.parametrize("cls", [CornetteShanks, HenyeyGreenstein])
@pytest.mark.parametrize("g", [1.0, -1.0, 1.5, math.nan, math.inf])
def test_bad_g(cls, g):
    with raises_named("g"):
        cls(g)


def test_unknown_phase_key():
    data = sa.bruneton2017().to_dict()
    data["constituents"]["aerosol"]["phase"] = {"type": "cornette_shanks", "gg": 0.5}
    with raises_named("phase.gg"):
        Atmosphere.from_dict(data)
    data["constituents"]["aerosol"]["phase"] = {"type": "fournier_forand"}
    with raises_named("phase.type"):
        Atmosphere.from_dict(data)
    data["constituents"]["aerosol"]["phase"] = {"type": "mie", "cosines": [-1.0, 1.0]}
    with raises_named("phase.values"):
        Atmosphere.from_dict(data)


def test_unknown_spectrum_key():
    data = sa.bruneton2017().to_dict()
    data["constituents"]["rayleigh"]["scattering"]["colour"] = "blue"
    with raises_named("spectrum.colour"):
        Atmosphere.from_dict(data)


@pytest.mark.parametrize("ssa", [1.01, -0.1, math.nan])
def test_bad_single_scattering_albedo(ssa):
    with raises_named("aerosol.single_scattering_albedo"):
        Aerosol(single_scattering_albedo=ssa)


@pytest.mark.parametrize("beta", [-1e-6, -0.1, math.inf, math.nan])
def test_bad_angstrom_beta(beta):
    with raises_named("aerosol.angstrom_beta"):
        Aerosol(angstrom_beta=beta)


def test_bad_angstrom_alpha():
    with raises_named("aerosol.angstrom_alpha"):
        Aerosol(angstrom_alpha=7.0)


def test_aerosol_needs_exactly_one_extinction():
    table = TabulatedSpectrum((400.0, 700.0), (1e-5, 1e-5))
    with raises_named("aerosol.extinction"):
        Aerosol(extinction=table)  # Angstrom defaults still set: two descriptions
    with raises_named("aerosol.extinction"):
        Aerosol(angstrom_alpha=None, angstrom_beta=None)  # none


@pytest.mark.parametrize("scale", [-1.0, 1e4, math.nan])
def test_bad_density_scale(scale):
    with raises_named("rayleigh.density_scale"):
        Rayleigh(density_scale=scale)
    with raises_named("aerosol.density_scale"):
        Aerosol(density_scale=scale)


def test_bad_ozone_column():
    with raises_named("ozone.column_du"):
        Absorber(column_du=-10.0)
    with raises_named("ozone.column_du"):
        Absorber(column_du=300.0, number_density_per_m3=1e18)


def test_bad_constituent_name():
    with raises_named("name"):
        Rayleigh(name="not an identifier")


# --- ground albedo -------------------------------------------------------------------------

@pytest.mark.parametrize("albedo", [1.2, -0.1, math.nan, math.inf, "white"])
def test_bad_ground_albedo_number(albedo):
    with raises_named("ground_albedo"):
        Atmosphere(ground_albedo=albedo)


def test_ground_albedo_above_one():
    with raises_named("ground_albedo"):
        Atmosphere(ground_albedo=1.5)
    with raises_named("ground_albedo"):
        Atmosphere(ground_albedo=TabulatedSpectrum((400.0, 500.0, 600.0), (0.2, 1.1, 0.3)))


# --- wavelengths ----------------------------------------------------------------------------

def test_wavelength_outside_ozone_table():
    with raises_named("wavelengths_nm"):
        Scene(wavelengths=[300.0])
    with raises_named("wavelengths_nm"):
        Scene.from_dict(scene_dict(spectral={"wavelengths": [550.0, 900.0]}))
    # Without ozone the same wavelength is fine (Rayleigh and aerosol cover 280-4000 nm).
    Scene(atmosphere=sa.rayleigh_only(), wavelengths=[300.0])


def test_wavelength_outside_solar_table():
    with raises_named("wavelengths[0]"):
        Scene(atmosphere=sa.rayleigh_only(), wavelengths=[100.0])


def test_bad_wavelength_set():
    with raises_named("wavelengths"):
        Scene(wavelengths="infrared")
    with raises_named("step_nm"):
        Scene.from_dict(scene_dict(spectral={"wavelengths": {"start_nm": 400.0, "stop_nm": 500.0,
                                                             "step_nm": 0.0}}))
    with raises_named("spectral.resolution"):
        Scene.from_dict(scene_dict(spectral={"wavelengths": "rgb", "resolution": 5}))


# --- dictionaries, scene files -----------------------------------------------------------------

def test_unknown_constituent_key():
    data = sa.bruneton2017().to_dict()
    data["constituents"]["aerosol"]["angstrom_betta"] = 0.1
    with raises_named("aerosol.angstrom_betta"):
        Atmosphere.from_dict(data)
    with raises_named("aerosol.angstrom_betta"):
        Scene.from_dict(scene_dict(atmosphere={"preset": "bruneton2017",
                                               "constituents": {"aerosol": {"angstrom_betta": 0.1}}}))


def test_unknown_constituent_kind():
    with raises_named("constituent.kind"):
        Atmosphere.from_dict({"constituents": {"water": {"kind": "cloud"}}})


def test_unknown_atmosphere_key():
    with raises_named("atmosphere.pressure"):
        Scene.from_dict(scene_dict(atmosphere={"preset": "bruneton2017", "pressure": 1013.0}))


def test_duplicate_constituent_names():
    with raises_named("constituents"):
        Atmosphere(constituents=(Rayleigh(), Rayleigh()))
    with raises_named("constituents"):
        Atmosphere(constituents=(Aerosol(name="haze"), Aerosol(name="haze", angstrom_beta=0.1)))
    # Two dict entries that rename themselves to the same name.
    with raises_named("constituents"):
        Atmosphere.from_dict({"constituents": {"a": {"kind": "rayleigh", "name": "air"},
                                               "b": {"kind": "rayleigh", "name": "air"}}})


def test_non_constituent():
    with raises_named("constituents"):
        Atmosphere(constituents=(ExponentialProfile(8000.0),))


@pytest.mark.parametrize("kind", ["orthographic", "", None])
def test_bad_camera_type(kind):
    with raises_named("camera.type"):
        Camera(type=kind)


@pytest.mark.parametrize("field,value", [("width", 0), ("width", 16385), ("height", -4), ("height", 12.5),
                                         ("width", True), ("height", "128")])
def test_bad_camera_size(field, value):
    with raises_named(f"camera.{field}"):
        Camera(**{field: value})


def test_bad_camera_fov():
    with raises_named("camera.fov_deg"):
        Camera(type="perspective", fov_deg=180.0)
    with raises_named("camera.fov_deg"):
        Camera(type="fisheye", fov_deg=0.0)


def test_unknown_camera_key():
    with raises_named("camera.resolution"):
        Scene.from_dict(scene_dict(camera={"resolution": 256}))


@pytest.mark.parametrize("field,value", [("spp", 0), ("spp", -1), ("spp", 2.0), ("passes", 1),
                                         ("seed", -1), ("max_depth", 0)])
def test_bad_render_settings(field, value):
    with raises_named(f"render.{field}"):
        RenderSettings(**{field: value})


def test_spp_zero_in_scene():
    with raises_named("render.spp"):
        Scene.from_dict(scene_dict(render={"spp": 0}))


@pytest.mark.parametrize("zenith", [200.0, -1.0, math.nan, math.inf])
def test_bad_sun_zenith(zenith):
    with raises_named("sun.zenith_deg"):
        Sun(zenith_deg=zenith)


def test_sun_zenith_200_in_scene():
    with raises_named("sun.zenith_deg"):
        Scene.from_dict(scene_dict(sun={"zenith_deg": 200.0}))


def test_bad_sun_time_and_place():
    with raises_named("sun.time"):
        Sun.at("yesterday at noon", 45.0, 5.0)
    with raises_named("sun.latitude_deg"):
        Sun.at("2024-03-20T12:00:00+00:00", 95.0, 5.0)
    with raises_named("sun.zenith_deg"):
        Sun.from_dict({"time": "2024-03-20T12:00:00+00:00", "latitude_deg": 0.0, "longitude_deg": 0.0,
                       "zenith_deg": 10.0})
    with raises_named("sun.longitude_deg"):
        Sun.from_dict({"time": "2024-03-20T12:00:00+00:00", "latitude_deg": 0.0})
    with raises_named("sun.limb_darkening"):
        Sun(limb_darkening="yes")


def test_bad_observer_altitude():
    with raises_named("observer.altitude_m"):
        Observer(altitude_m=-10.0)
    with raises_named("observer.height"):
        Scene.from_dict(scene_dict(observer={"height": 10.0}))


def test_unknown_preset():
    with raises_named("atmosphere.preset"):
        sa.preset("earth")
    with raises_named("atmosphere.preset"):
        Scene.from_dict(scene_dict(atmosphere={"preset": "bruneton2018"}))


@pytest.mark.parametrize("turbidity", [0.5, 60.0, math.nan])
def test_bad_turbidity(turbidity):
    with raises_named("turbidity"):
        sa.from_turbidity(turbidity)


def test_unknown_top_level_table(tmp_path):
    path = tmp_path / "scene.toml"
    path.write_text('[atmosphere]\npreset = "bruneton2017"\n\n[lighting]\nsun_zenith = 30.0\n')
    with raises_named("lighting"):
        load_scene(path)


def test_missing_and_malformed_scene_file(tmp_path):
    with raises_named("scene"):
        load_scene(tmp_path / "missing.toml")
    path = tmp_path / "broken.toml"
    path.write_text("[atmosphere\npreset = 1\n")
    with raises_named("scene"):
        load_scene(path)


def test_integer_checks_name_the_entry():
    from skyref.validation import check_int, check_int_tuple
    from skyref.errors import ParameterError

    assert check_int("n", 4, 2, 8, even=True) == 4
    for bad, problem in ((9, "out of range"), (3, "odd"), (4.0, "not an integer"), (True, "not an integer")):
        with pytest.raises(ParameterError, match=problem):
            check_int("n", bad, 2, 8, even=True)
    assert check_int_tuple("size", [32, 128, 32], 3, 2, 1024, even_axes=(1,)) == (32, 128, 32)
    with pytest.raises(ParameterError) as info:
        check_int_tuple("size", (32, 127, 32), 3, 2, 1024, even_axes=(1,))
    assert info.value.name == "size[1]"
    with pytest.raises(ParameterError, match="wrong length"):
        check_int_tuple("size", (32, 128), 3, 2, 1024)


def test_view_arguments_are_checked_and_normalised():
    from skyref.validation import check_view
    from skyref.errors import ParameterError

    dirs, sun, altitude = check_view([[0.0, 0.0, 1.0]], [0.0, 3.0, 4.0], 10)
    assert sun.tolist() == [0.0, 0.6, 0.8] and altitude == 10.0 and dirs.shape == (1, 3)
    with pytest.raises(ParameterError, match="directions"):
        check_view([[0.0, 0.0, 2.0]], [0.0, 0.0, 1.0], 0.0)
    with pytest.raises(ParameterError, match="sun_direction"):
        check_view([[0.0, 0.0, 1.0]], [0.0, 0.0, 0.0], 0.0)
    with pytest.raises(ParameterError, match="observer_altitude_m"):
        check_view([[0.0, 0.0, 1.0]], [0.0, 0.0, 1.0], -1.0)
