"""Tables of a LUT method as an engine loads them: EXR textures in the paper's texture layout,
a JSON of the parametrization's constants and a GLSL snippet that reads them
(``skyref export-lut``).

Files written into one directory, ``<method>`` being the method's name (sizes: the papers'
defaults; width x height, x along the width):

- Bruneton 2017 (every table view-independent):

  - ``<method>_transmittance.exr``: T(r, mu), 256 x 64 (x: mu, y: r);
  - ``<method>_scattering.exr``: S(r, mu, mu_s, nu) as the reference implementation's 3-D texture
    (width NU x MU_S: the nu slices side by side, height MU, depth R), its R depth slices stacked
    from the top of the image down, 256 x (128 x 32): the EXR's scanlines in order are the 3-D
    texture's memory. RGB; RGBA with ``combined_mie`` (A: single Mie of the R channel);
  - ``<method>_single_mie.exr``: single Mie in the same layout (without ``combined_mie``);
  - ``<method>_irradiance.exr``: E(r, mu_s), 64 x 16 (x: mu_s, y: r).

- Hillaire 2020:

  - ``<method>_transmittance.exr``: T(r, mu), 256 x 64, Bruneton's parametrization;
  - ``<method>_multiple_scattering.exr``: Psi_ms(r, mu_s), 32 x 32 (x: mu_s, y: r), unless the
    method's ``multiple_scattering`` is off;
  - ``<method>_sky_view.exr``: the sky view, 192 x 108 (x: azimuth from the sun, y: zenith
    angle), for the scene's observer altitude and sun (a per-view table: an engine rebuilds it
    when they move); not written for an observer above the atmosphere, where the method ray
    marches.

The aerial-perspective volume of Hillaire 2020 is not exported: it belongs to one camera and
frame. ``<method>.json`` states what each file holds (units, channels, the mappings of its
coordinates with the names of the reference implementations' functions), the constants of the
parametrization (radii, mu_s_min, sun angular radius, table sizes), the wavelength each
channel stands for and the solar irradiance in it; ``<method>.glsl`` holds the texture-coordinate
functions with these constants filled in (templates in ``skyref/lut/glsl/``).

Conventions: channels R, G, B hold the method's three wavelengths in its order (by default
skyref's ``rgb`` set, 680, 550, 440 nm). Texel row 0 is the EXR's first scanline (the top of
the image in a viewer): upload the scanlines in order and row 0 gets v = 0.5 / height, as in
OpenGL. Coordinates map a unit-range x to texel centres, u = 0.5 / n + x (1 - 1 / n), and
tables are read with linear filtering and clamp-to-edge. Pixels are HALF where the method
stores the table in float16 and FLOAT otherwise (Bruneton 2017 keeps transmittance and
irradiance in float32 whatever the precision, as its reference implementation does), so the
files hold exactly the values the method interpolates. Lengths in metres. The transmittance
between two points of a ray is exp(-(tau_a - tau_b)) with tau = -ln T the optical depth to the
top: convert the transmittance texture to a float32 optical-depth texture once at load and
interpolate that, as skyref does (:class:`~skyref.lut.transmittance.TransmittanceTable`); the
paper's ratio of two transmittances fails on grazing hazy rays, where T underflows.

The directory appears at once when it does not exist yet (the files are written into a
temporary directory beside it, then moved); into an existing directory every file is moved
atomically, the JSON last.
"""

from __future__ import annotations

import json
import os
import shutil
import string
import uuid
from importlib import resources

import numpy as np
import OpenEXR

from skyref import __version__
from skyref.errors import ParameterError
from skyref.io.json_numpy import numpy_default
from skyref.lut import REGISTRY, lut_method
from skyref.lut.table import PRECISIONS
from skyref.atmosphere.spectra import wavelength_grid
from skyref.validation import check_array, check_choice

__all__ = ["EXPORTABLE", "CHANNELS", "TEXEL_CENTRES", "check_method", "rgb_wavelengths", "build_method",
           "export_lut"]

#: LUT methods whose tables can be exported.
EXPORTABLE = ("bruneton2017", "hillaire2020")
#: Texture channels, one per wavelength.
CHANNELS = ("R", "G", "B")
#: How every table's coordinates sit on its texels.
TEXEL_CENTRES = ("u(x, n) = 0.5 / n + x (1 - 1 / n) for a unit-range x on an axis of n texels (first and last texel "
                 "centres at x = 0 and x = 1; Bruneton 2017, GetTextureCoordFromUnitRange); linear filtering, "
                 "clamp to edge; texel row 0 = the EXR's first scanline")
_RHO_H = "rho = sqrt(r^2 - R^2), H = sqrt(R_t^2 - R^2) (R, R_t: bottom and top radius)"
_TRANSMITTANCE_MAPPING = {
    "x": "mu: (d - d_min) / (d_max - d_min), d the distance to the top along mu, d_min = R_t - r, d_max = rho + H",
    "y": "r: rho / H, " + _RHO_H,
    "reference": "Bruneton 2017, GetTransmittanceTextureUvFromRMu",
    "glsl": "transmittance_uv"}


def check_method(name: str) -> str:
    """``name`` if it is a LUT method with exportable tables, else a ParameterError naming --method."""
    return check_choice("--method", name, EXPORTABLE)


def rgb_wavelengths(spec="rgb") -> np.ndarray:
    """The three wavelengths (nm) of the texture channels: ``"rgb"`` (680, 550, 440 nm), three
    numbers, or a string of three comma-separated numbers."""
    if isinstance(spec, str) and spec != "rgb":
        try:
            spec = [float(x) for x in spec.split(",")]
        except ValueError:
            raise ParameterError("--wavelengths", spec, "'rgb' or three wavelengths in nm, e.g. 680,550,440",
                                 "not numbers") from None
    wavelengths = wavelength_grid(spec) if isinstance(spec, str) else check_array("--wavelengths", spec, 0.0)
    if wavelengths.size != len(CHANNELS) or len(set(wavelengths.tolist())) != len(CHANNELS):
        raise ParameterError("--wavelengths", wavelengths.tolist(), "three distinct wavelengths (nm), one per "
                             "texture channel R, G, B",
                             f"{wavelengths.size} given" if wavelengths.size != len(CHANNELS) else "not distinct")
    return wavelengths


def build_method(name: str, scene, wavelengths="rgb", precision: str = "float32", options: dict | None = None):
    """The method ``name`` for ``scene``'s atmosphere (not yet precomputed) on the texture
    channels' wavelengths, its tables stored in ``precision``; ``options`` are its constructor's
    (table sizes, orders, ...; not ``precision``). The sun's angular radius is the scene's
    unless an option sets it. Every check runs here, before any work."""
    check_method(name)
    precision = check_choice("--precision", precision, PRECISIONS)
    options = dict(options or {})
    REGISTRY.check_options(name, options, parameter="--option")
    if "precision" in options:
        raise ParameterError("--option", "precision", "any other option of the method",
                             "the storage precision is --precision")
    options.setdefault("sun_angular_radius_deg", scene.sun.angular_radius_deg)
    return lut_method(name, scene.atmosphere, rgb_wavelengths(wavelengths), precision=precision, **options)


# --- what each method exports -------------------------------------------------------------------------

class _Texture:
    """One EXR: ``values`` (height, width, channels) as stored, the storage ``precision`` and
    the JSON entry describing it."""

    def __init__(self, name: str, values, precision: str, description: dict, depth: int = 1):
        self.name, self.precision = name, precision
        values = np.asarray(values)
        self.values = values.reshape((-1,) + values.shape[-2:])            # 3-D tables: slices stacked
        height, width, channels = self.values.shape
        self.channels = (*CHANNELS, "A")[:channels]
        self.description = {"pixel_type": precision, "width": width, "height": height // depth,
                            **({"depth": depth} if depth > 1 else {}), "channels": list(self.channels),
                            **description}


def _per_channel(method, quantity) -> np.ndarray:
    """``quantity(channel)`` (a Dr.Jit function of a UInt32 channel) for every channel, NumPy."""
    import mitsuba as mi  # lazy: loaded with the method (its libLLVM is chosen first)

    return np.array([float(quantity(mi.UInt32(k)).numpy()[0]) for k in range(method.channels)])


def _bruneton(method) -> tuple[list, dict, dict]:
    """(textures, constants, GLSL substitutions) of :class:`~skyref.lut.bruneton.Bruneton2017`."""
    width = method.nu_size * method.mu_s_size
    r_size, mu_size = method.r_size, method.mu_size
    combined = method.combined_mie
    coordinates = {
        "x": "nu x mu_s: texel column i_nu * MU_S + i_mu_s; a lookup reads the neighbouring nu slices at "
             "x = (floor(X) + u_mu_s) / NU and (floor(X) + 1 + u_mu_s) / NU, X = u_nu (NU - 1), and blends them "
             "with weight X - floor(X); u_nu = (nu + 1) / 2 (nu on grid points i / (NU - 1), not texel centres); "
             "u_mu_s texel-centred of max(1 - a / A, 0) / (1 + a), a = (d - d_min) / (d_max - d_min) with d the "
             "distance from the ground to the top along mu_s, d_min = R_t - R, d_max = H, and A the same for "
             "mu_s_min",
        "y": "mu: rays that hit the ground on the lower half, u_mu = 0.5 - 0.5 u(x, MU / 2) with x = (d - (r - R)) "
             "/ (rho - (r - R)), d the distance to the ground; the others on the upper half, "
             "u_mu = 0.5 + 0.5 u(x, MU / 2) with x = (d - (R_t - r)) / (rho + H - (R_t - r)), d the distance to "
             "the top",
        "z": "r: rho / H, " + _RHO_H,
        "reference": "Bruneton 2017, GetScatteringTextureUvwzFromRMuMuSNu and GetScattering",
        "glsl": "scattering_uvwz, scattering_lookup"}
    scattering = ("single Rayleigh scattering without its phase function plus scattering orders 2 to "
                  "scattering_orders divided by the Rayleigh phase function; radiance = value x phase")
    textures = [
        _Texture("transmittance", method.transmittance.table.numpy(), method.transmittance.table.precision,
                 {"quantity": "transmittance from (r, mu) to the top of the atmosphere", "units": "1",
                  **_TRANSMITTANCE_MAPPING}),
        _Texture("scattering", method.scattering.numpy(), method.scattering.precision,
                 {"quantity": scattering + (" (A: single Mie scattering of the R channel without its phase "
                                            "function)" if combined else ""),
                  "units": "W m^-2 nm^-1 (times a phase function, sr^-1: W m^-2 sr^-1 nm^-1)",
                  "layout": f"3-D texture {width} x {mu_size} x {r_size} (x, y, z); in the EXR the z slices are "
                            f"stacked from the top down: scanline i_r * {mu_size} + i_mu", **coordinates},
                 depth=r_size)]
    if not combined:
        textures.append(_Texture("single_mie", method.single_mie.numpy(), method.single_mie.precision,
                                 {"quantity": "single Mie scattering without its phase function",
                                  "units": "W m^-2 nm^-1", "layout": "as scattering",
                                  "reference": "Bruneton 2017, single_mie_scattering_texture",
                                  "glsl": "scattering_uvwz, scattering_lookup"}, depth=r_size))
    textures.append(_Texture(
        "irradiance", method.irradiance.numpy(), method.irradiance.precision,
        {"quantity": "sky irradiance (no direct sun) on a horizontal surface at radius r, sun at zenith cosine mu_s",
         "units": "W m^-2 nm^-1", "x": "mu_s: (mu_s + 1) / 2", "y": "r: (r - R) / (R_t - R)",
         "reference": "Bruneton 2017, GetIrradianceTextureUvFromRMuS", "glsl": "irradiance_uv"}))
    constants = {
        "mu_s_min": method.mu_s_min, "max_sun_zenith_deg": method.max_sun_zenith_deg,
        "scattering_size": {"r": r_size, "mu": mu_size, "mu_s": method.mu_s_size, "nu": method.nu_size},
        "scattering_orders": method.scattering_orders, "combined_mie": combined,
        "rayleigh_scattering_per_m": method.rayleigh_scattering, "mie_scattering_per_m": method.mie_scattering,
        "mie_extrapolation": ("single Mie of channel k = S_k A / S_R (beta_R,R / beta_M,R) (beta_M,k / beta_R,k), "
                              "beta the scattering coefficients above (GetExtrapolatedSingleMieScattering)"
                              if combined else None),
        "ground": "albedo / pi (E_sun + E_sky) T + L_in: E_sun = solar irradiance x T to the sun x max(mu_s, 0), "
                  "E_sky = irradiance table (GetSunAndSkyIrradiance)"}
    glsl = {"R_SIZE": r_size, "MU_SIZE": mu_size, "MU_S_SIZE": method.mu_s_size, "NU_SIZE": method.nu_size,
            "MU_S_MIN": _glsl_float(method.mu_s_min),
            "IRRADIANCE_WIDTH": method.irradiance_width, "IRRADIANCE_HEIGHT": method.irradiance_height}
    return textures, constants, glsl


def _hillaire(method, sun_direction, observer_altitude_m: float) -> tuple[list, dict, dict]:
    """(textures, constants, GLSL substitutions) of :class:`~skyref.lut.hillaire.Hillaire2020`,
    the sky view for the sun towards ``sun_direction`` (east-north-up) seen from ``observer_altitude_m``."""
    textures = [_Texture("transmittance", method.transmittance.table.numpy(), method.transmittance.table.precision,
                         {"quantity": "transmittance from (r, mu) to the top of the atmosphere", "units": "1",
                          **_TRANSMITTANCE_MAPPING})]
    per_unit_sun = "sr^-1 (radiance per unit solar irradiance: times solar_irradiance, W m^-2 sr^-1 nm^-1)"
    if method.multiple_scattering_table is not None:
        table = method.multiple_scattering_table
        textures.append(_Texture(
            "multiple_scattering", table.numpy(), table.precision,
            {"quantity": "Psi_ms, light of scattering orders >= 2 at a point, isotropic: a point scatters "
                         "(sigma_s,Rayleigh + sigma_s,Mie) Psi_ms solar_irradiance towards every direction",
             "units": per_unit_sun, "x": "mu_s: (mu_s + 1) / 2", "y": "r: (r - R) / (R_t - R)",
             "reference": "Hillaire 2020, GetMultipleScattering (texel-centred here)",
             "glsl": "multiple_scattering_uv"}))
    sun = np.asarray(sun_direction, dtype=np.float64).reshape(3)
    sun = sun / np.linalg.norm(sun)
    r = method.optics.bottom_radius + float(observer_altitude_m)
    sky_view = None
    if r <= method.optics.top_radius:
        sky_view = {"observer_altitude_m": float(observer_altitude_m), "sun_zenith_cosine": float(sun[2])}
        table = method.sky_view(r, float(sun[2]))
        textures.append(_Texture(
            "sky_view", table.numpy(), table.precision,
            {"quantity": "in-scattered radiance from the observer to the ground or the top of the atmosphere "
                         "(neither the ground nor the sun disk)", "units": per_unit_sun, **sky_view,
             "x": "azimuth phi between view and sun (horizontal projections): sqrt((1 - cos phi) / 2)",
             "y": "view zenith angle theta, with theta_h = pi - acos(rho / r) the horizon's and beta = pi - "
                  "theta_h: 0.5 (1 - sqrt(1 - theta / theta_h)) above the horizon, 0.5 (1 + sqrt((theta - "
                  "theta_h) / beta)) below (rays that hit the ground)",
             "reference": "Hillaire 2020, SkyViewLutParamsToUv (texel-centred here)", "glsl": "sky_view_uv"}))
    constants = {
        "multiple_scattering_size": list(method.multiple_scattering_size) if method.multiple_scattering else None,
        "sky_view_size": list(method.sky_view_size), "sky_view": sky_view,
        "not_exported": "the aerial-perspective volume (one per camera and frame)"
                        + ("" if sky_view else "; the sky view (the observer is above the atmosphere)"),
        "ground": "T to the ground x albedo (T(R, mu_s) max(mu_s, 0) / pi + Psi_ms(R, mu_s)) x solar_irradiance, "
                  "added to the sky view where the ray hits the ground"}
    glsl = {"MULTIPLE_SCATTERING_WIDTH": method.multiple_scattering_size[0],
            "MULTIPLE_SCATTERING_HEIGHT": method.multiple_scattering_size[1],
            "SKY_VIEW_WIDTH": method.sky_view_size[0], "SKY_VIEW_HEIGHT": method.sky_view_size[1]}
    return textures, constants, glsl


# --- writing ------------------------------------------------------------------------------------------

def _glsl_float(x: float) -> str:
    """A GLSL float literal of ``x`` (shortest round trip; always with a decimal point or exponent)."""
    text = repr(float(x))
    return text if any(c in text for c in ".eE") else text + ".0"


def _write_exr(texture: _Texture, path: str, method_name: str) -> None:
    dtype = np.float16 if texture.precision == "float16" else np.float32
    channels = {name: np.ascontiguousarray(texture.values[..., k].astype(dtype))
                for k, name in enumerate(texture.channels)}
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage,
              "skyref.method": method_name, "skyref.table": texture.name,
              "skyref.description": f"{method_name}.json"}
    with OpenEXR.File(header, channels) as exr:
        exr.write(path)


def _glsl(method_name: str, method, glsl: dict) -> str:
    template = resources.files("skyref.lut").joinpath("glsl", f"{method_name}.glsl").read_text()
    width, height = method.transmittance.width, method.transmittance.height
    return string.Template(template).substitute(
        VERSION=__version__, BOTTOM_RADIUS=_glsl_float(method.optics.bottom_radius),
        TOP_RADIUS=_glsl_float(method.optics.top_radius), TRANSMITTANCE_WIDTH=width,
        TRANSMITTANCE_HEIGHT=height, **glsl)


def _write_text(path: str, text: str) -> None:
    with open(path, "w") as f:
        f.write(text)


def _publish(writers: dict, directory) -> None:
    """Write every file (name -> function writing it to a path) into a temporary directory beside
    ``directory``, then make it ``directory`` at once when that does not exist, else move the files
    in one by one (each move atomic) in the order given."""
    directory = os.path.abspath(os.fspath(directory))
    parent = os.path.dirname(directory)
    os.makedirs(parent, exist_ok=True)
    staging = os.path.join(parent, f".{os.path.basename(directory)}.{uuid.uuid4().hex[:12]}.tmp")
    os.mkdir(staging)                         # mode 0777 less the umask, as for the directory it becomes
    try:
        for file_name, write in writers.items():
            path = os.path.join(staging, file_name)
            write(path)
            with open(path, "rb") as f:
                os.fsync(f.fileno())
        if os.path.isdir(directory):
            for file_name in writers:
                os.replace(os.path.join(staging, file_name), os.path.join(directory, file_name))
            os.rmdir(staging)
        else:
            os.replace(staging, directory)
    except BaseException:
        shutil.rmtree(staging, ignore_errors=True)
        raise


def export_lut(method, directory, *, sun_direction=(0.0, 0.0, 1.0), observer_altitude_m: float = 0.0,
               source: dict | None = None) -> dict:
    """Write the precomputed tables of ``method`` (Bruneton 2017 or Hillaire 2020, three
    wavelengths) into ``directory`` (see the module docstring); ``sun_direction`` (east-north-up)
    and ``observer_altitude_m`` (m) pick Hillaire's sky view, ``source`` (e.g. the scene's name)
    goes into the JSON. Returns the JSON's content."""
    name = check_method(method.name)
    if method.channels != len(CHANNELS):
        raise ParameterError("wavelengths", list(method.wavelengths_nm), "three wavelengths (texture channels "
                             "R, G, B)", f"{method.channels} given")
    if method.precompute_seconds is None:
        raise RuntimeError(f"{name}: call precompute() before export_lut()")
    if name == "bruneton2017":
        textures, constants, glsl = _bruneton(method)
    else:
        textures, constants, glsl = _hillaire(method, sun_direction, observer_altitude_m)
    files = {t.name: f"{name}_{t.name}.exr" for t in textures}
    aerosol = method.optics.mie[0].model.phase.to_dict() if method.optics.mie else None
    record = {
        "format": "skyref LUT export 1", "skyref_version": __version__, "method": name,
        "source": source or {}, "options": getattr(method, "options", {}),
        "precision": method.precision,
        "channels": {c: {"wavelength_nm": w, "solar_irradiance": e}
                     for c, w, e in zip(CHANNELS, method.wavelengths_nm, method.solar_irradiance)},
        "wavelengths_nm": method.wavelengths_nm, "solar_irradiance": method.solar_irradiance,
        "units": {"length": "m", "wavelength": "nm", "solar_irradiance": "W m^-2 nm^-1 at the top of the "
                  "atmosphere, perpendicular to the beam", "radiance": "W m^-2 sr^-1 nm^-1", "angle": "rad"},
        "bottom_radius_m": method.optics.bottom_radius, "top_radius_m": method.optics.top_radius,
        "sun_angular_radius_rad": method.sun_angular_radius, "atmosphere": method.atmosphere.to_dict(),
        "ground_albedo": _per_channel(method, method.optics.ground_albedo),
        "phase_functions": {"rayleigh": "3 / (16 pi) (1 + nu^2)", "mie": aerosol},
        "texel_centres": TEXEL_CENTRES, **constants,
        "tables": {t.name: {"file": files[t.name], **t.description} for t in textures},
        "glsl": f"{name}.glsl"}
    shader = _glsl(name, method, glsl)

    _publish({**{files[t.name]: (lambda path, t=t: _write_exr(t, path, name)) for t in textures},
              f"{name}.glsl": lambda path: _write_text(path, shader),
              f"{name}.json": lambda path: _write_text(path, json.dumps(record, indent=2, default=numpy_default)
                                                       + "\n")}, directory)
    return record
