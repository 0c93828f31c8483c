"""Where a line-integral path should scatter to: a guide built from the light the sky scatters.

A path that scatters at a point x goes on along a direction omega, and the light it gathers
there is the radiance scattered towards x from omega: first of all the sunlight scattered once
along its next segment, L1(x, omega), then the light scattered more often, Lm(x, omega). The
phase function alone does not know where that light is: at twilight it comes from a few degrees
around the sun's azimuth just above the horizon, where the air is still lit, and a path that
scatters in the planet's shadow sends most of its directions elsewhere. :class:`ScatteredLightGuide`
tabulates, per altitude,

    L(h, theta, phi) = L1 + Lm,   theta the zenith angle of omega, phi its azimuth from the sun's,

on the observer's vertical (altitudes h_i = H (i / (n - 1))^2, finer near the ground; theta in
steps of 2 deg, phi in [0, 180] deg in steps of 5 deg: the sky is mirror-symmetric about the sun's
vertical plane), at the grid wavelengths nearest 440, 550 and 680 nm (their mean):

* L1 at each cell's centre, with the same quadrature as the camera segment's single scattering
  (:meth:`skyref.plugins.line_integral.LineIntegral.integrate`): sharp where it is sharp (the
  aureole, the twilight glow);
* Lm, where the integrator adds it (:meth:`ScatteredLightGuide.add_multiple_scattering`), from a
  pilot: orders >= 2 traced from each layer at the centres of coarser cells (``PILOT_ZENITH_BINS``
  x ``PILOT_AZIMUTH_BINS``, 10 x 20 deg; multiply scattered light is smooth), each spread over
  the fine cells it covers.

A cell's probability is its L x solid angle plus ``GUIDE_FLOOR`` of the layer's mean, so that no
direction is out of reach (a layer that no light reaches is uniform). The table's radiance itself
(:meth:`GuideAtVertex.radiance`, with the same floor) tells the integrator's Russian roulette what
a path is expected to gather from a vertex on. Directions are drawn
from the layer below or above the point's altitude (stochastically, by where it lies between
them), a cell by its probability, uniformly in cos theta and phi within the cell, phi's sign at
random; the density of a direction (sr^-1) is the same mixture of the two layers' cells.

At a point elsewhere than above the observer, the guide is read in the local frame (local zenith,
the sun's local azimuth): the sun's elevation there differs, and the guide is then only an
approximation of L — it is a sampling density, so the estimate stays unbiased whatever its
quality. The integrator mixes it with the phase function's own sampling (one-sample multiple
importance sampling, balance heuristic), and resamples that mixture's directions by phase function
x guide density (:meth:`~skyref.plugins.integrator.AtmosphereIntegrator._scatter_direction`).

References
----------
E. Veach and L. J. Guibas, "Optimally Combining Sampling Techniques for Monte Carlo Rendering",
SIGGRAPH 1995 (one-sample MIS).
"""

from __future__ import annotations

import math

import drjit as dr
import mitsuba as mi
import numpy as np

from skyref.plugins.drjit_namespace import channel_mean
from skyref.plugins.line_integral import GreyProxy

__all__ = ["GUIDE_LAYERS", "GUIDE_ZENITH_BINS", "GUIDE_AZIMUTH_BINS", "GUIDE_FLOOR", "PILOT_ZENITH_BINS",
           "PILOT_AZIMUTH_BINS", "ScatteredLightGuide", "GuideAtVertex"]

#: Altitude layers of the table (quadratic in altitude, 0 to the top of the atmosphere).
GUIDE_LAYERS = 24

#: Zenith-angle bins (0-180 deg) and azimuth bins (0-180 deg from the sun's azimuth). Twice finer in
#: zenith changed the variance at twilight by less than its noise (measured, sun zenith 96 deg).
GUIDE_ZENITH_BINS = 90
GUIDE_AZIMUTH_BINS = 36

#: The pilot's coarser cells (:meth:`ScatteredLightGuide.pilot_directions`): 10 deg in zenith, 20 in
#: azimuth, each covering 5 x 4 of the table's. A pilot at the table's own resolution (90 x 36, 16
#: paths each) guided no better (hazy sky, turbidity 6, sun zenith 60: summed worst-channel variance
#: of 6 views 3.44 against 3.63, within the noise) for 20x its paths.
PILOT_ZENITH_BINS = 18
PILOT_AZIMUTH_BINS = 9

#: Share of a layer's mean spread uniformly (in solid angle) over its cells.
GUIDE_FLOOR = 0.05

#: Wavelengths (nm) at which the table's single scattering is computed: the grid's nearest.
GUIDE_WAVELENGTHS_NM = (440.0, 550.0, 680.0)


def guide_channels(wavelengths_nm) -> list[int]:
    """The indices of the grid's wavelengths nearest ``GUIDE_WAVELENGTHS_NM`` (each once)."""
    wavelengths_nm = np.asarray(wavelengths_nm)
    return sorted({int(np.argmin(np.abs(wavelengths_nm - w))) for w in GUIDE_WAVELENGTHS_NM})


def _sun_frame(up, sun):
    """The local horizontal unit vectors towards the sun's azimuth and 90 deg from it (any
    horizontal pair where the sun is at the local zenith)."""
    horizontal = sun - dr.dot(sun, up) * up
    length = dr.norm(horizontal)
    towards_sun = dr.select(length > 1e-6, horizontal / dr.maximum(length, 1e-30), mi.coordinate_system(up)[0])
    return towards_sun, dr.cross(up, towards_sun)


class ScatteredLightGuide:
    """The tabulated guide (module docstring) for the ``line`` integral of an atmosphere in
    ``geometry``, lit by ``sun`` (the integrator's :class:`~skyref.plugins.integrator.SunLight`),
    built from single scattering; :meth:`add_multiple_scattering` adds a pilot's."""

    def __init__(self, line, geometry, sun, wavelengths_nm):
        self.sun_direction = sun.direction
        self.top = float(geometry.H)
        self.cells = GUIDE_ZENITH_BINS * GUIDE_AZIMUTH_BINS
        self.azimuth_step = math.pi / GUIDE_AZIMUTH_BINS
        cos_edges = np.cos(np.linspace(0.0, math.pi, GUIDE_ZENITH_BINS + 1))
        #: solid angle of one cell of each zenith bin (one side of the sun's plane), sr
        self._cell_solid_angle_sr = (cos_edges[:-1] - cos_edges[1:]) * self.azimuth_step
        self.cos_edges = mi.Float(cos_edges.astype(np.float32))
        self.cell_solid_angle = mi.Float(self._cell_solid_angle_sr.astype(np.float32))
        #: The grid's channels whose mean the table holds.
        self.channels = guide_channels(wavelengths_nm)
        self.single_scattering = self._single_scattering(line, geometry, sun)
        #: The pilot's multiply scattered radiance per fine cell and its layers' means
        #: (:meth:`add_multiple_scattering`; None until then).
        self.multiple = None
        self._tabulate(self.single_scattering)

    def pilot_directions(self) -> tuple[np.ndarray, np.ndarray]:
        """Where a pilot traces orders >= 2 for :meth:`add_multiple_scattering`: the altitudes of
        the layers (m; the ground layer at 1 m, the top one 1 m below the top, both inside the
        air) and the unit directions of the coarse cells' centres on the observer's vertical
        (PILOT_ZENITH_BINS x PILOT_AZIMUTH_BINS, zenith-major, in the observer's frame)."""
        altitudes = np.clip(self.top * (np.arange(GUIDE_LAYERS) / (GUIDE_LAYERS - 1)) ** 2, 1.0, self.top - 1.0)
        theta = (np.arange(PILOT_ZENITH_BINS) + 0.5) * (math.pi / PILOT_ZENITH_BINS)
        phi = (np.arange(PILOT_AZIMUTH_BINS) + 0.5) * (math.pi / PILOT_AZIMUTH_BINS)
        # the table's own frame on the observer's vertical, as NumPy vectors
        towards_sun, across = (np.array([float(dr.slice(c)) for c in v])
                               for v in _sun_frame(mi.Vector3f(0.0, 0.0, 1.0), self.sun_direction))
        theta, phi = np.meshgrid(theta, phi, indexing="ij")
        directions = ((np.sin(theta) * np.cos(phi))[..., None] * towards_sun
                      + (np.sin(theta) * np.sin(phi))[..., None] * across + np.cos(theta)[..., None] * [0.0, 0.0, 1.0])
        return altitudes, directions.reshape(-1, 3)

    def add_multiple_scattering(self, radiance) -> None:
        """Add a pilot's multiply scattered radiance to the table: ``radiance`` (layers,
        PILOT_ZENITH_BINS x PILOT_AZIMUTH_BINS), the mean over :attr:`channels` of orders >= 2
        arriving at each layer from :meth:`pilot_directions` (W m^-2 sr^-1 nm^-1), each spread
        over the fine cells it covers."""
        coarse = np.asarray(radiance, dtype=np.float64).reshape(GUIDE_LAYERS, PILOT_ZENITH_BINS, PILOT_AZIMUTH_BINS)
        #: The pilot's table, (layers, PILOT_ZENITH_BINS, PILOT_AZIMUTH_BINS).
        self.multiple_scattering = coarse
        fine = np.repeat(np.repeat(coarse, GUIDE_ZENITH_BINS // PILOT_ZENITH_BINS, axis=1),
                         GUIDE_AZIMUTH_BINS // PILOT_AZIMUTH_BINS, axis=2)
        self.multiple = self._radiance_table(fine)
        self._tabulate(self.single_scattering + fine)

    def _radiance_table(self, radiance) -> tuple:
        """``radiance`` (layers, zenith bins, azimuth bins; negative values, a pilot's noise, as 0)
        as a flat Float, and each layer's mean over the sphere (a Float of GUIDE_LAYERS)."""
        radiance = np.maximum(radiance, 0.0)
        layer_mean = (radiance * self._cell_solid_angle_sr[None, :, None]).sum(axis=(1, 2)) / (2.0 * math.pi)
        return mi.Float(radiance.ravel().astype(np.float32)), mi.Float(layer_mean.astype(np.float32))

    def _tabulate(self, radiance) -> None:
        """The cells' probabilities and cumulative sums per layer from ``radiance`` (layers,
        zenith bins, azimuth bins)."""
        cell_solid_angle = self._cell_solid_angle_sr
        mass = np.maximum(radiance, 0.0) * cell_solid_angle[None, :, None]
        layer_mass = mass.sum(axis=(1, 2), keepdims=True)
        mass = mass + GUIDE_FLOOR * layer_mass * cell_solid_angle[None, :, None] / (2.0 * math.pi)
        # a layer that no sunlight reaches (the sun far below the horizon, an empty atmosphere):
        # uniform in solid angle
        mass = np.where(layer_mass > 0.0, mass, cell_solid_angle[None, :, None])
        probability = (mass / mass.sum(axis=(1, 2), keepdims=True)).reshape(GUIDE_LAYERS, -1)
        cumulative = np.cumsum(probability, axis=1)
        cumulative[:, -1] = 1.0
        self.probability = mi.Float(probability.ravel().astype(np.float32))
        #: The table's radiance per cell and its layers' means (:meth:`_radiance_table`).
        self.radiance = self._radiance_table(radiance)
        self.cumulative = mi.Float(cumulative.ravel().astype(np.float32))

    def _single_scattering(self, line, geometry, sun):
        """L1 at the centres of the cells, (layers, zenith bins, azimuth bins), the mean over
        :attr:`channels` (W m^-2 sr^-1 nm^-1)."""
        # The cells' centres are computed in the kernel from the cell index: arrays loaded from
        # NumPy would specialise the kernel on their memory's alignment (Dr.Jit 1.5), which
        # varies from run to run, and this kernel takes ~17 s to compile.
        cell = dr.arange(mi.UInt32, GUIDE_LAYERS * self.cells)
        layer = cell // self.cells
        theta = (mi.Float((cell // GUIDE_AZIMUTH_BINS) % GUIDE_ZENITH_BINS) + 0.5) * (math.pi / GUIDE_ZENITH_BINS)
        phi = (mi.Float(cell % GUIDE_AZIMUTH_BINS) + 0.5) * self.azimuth_step
        altitude = self.top * dr.square(mi.Float(layer) / (GUIDE_LAYERS - 1))     # h_i = H (i / (n - 1))^2
        up = mi.Vector3f(0.0, 0.0, 1.0)                         # the observer's vertical
        towards_sun, across = _sun_frame(up, self.sun_direction)
        (sin_theta, cos_theta), (sin_phi, cos_phi) = dr.sincos(theta), dr.sincos(phi)
        d = (sin_theta * cos_phi) * towards_sun + (sin_theta * sin_phi) * across + cos_theta * up
        p = geometry.above_observer(altitude)
        h = geometry.altitude(p)
        length = dr.minimum(geometry.distance_to_ground(p, d, h), geometry.distance_to_top(p, d, h))
        indices = [mi.UInt32(i) for i in self.channels]
        channels = line.optics.channel_coefficients(indices)
        light, _, _ = line.integrate(channels, p, d, h, length, self.sun_direction,
                                     GreyProxy(channels, channels.zeros() + 1.0), forced_collision=False)
        e_sun = sun.channel_irradiance(indices)
        radiance = channel_mean(mi.ArrayXf([light[c] * e_sun[c] for c in range(len(indices))]))
        return radiance.numpy().astype(np.float64).reshape(GUIDE_LAYERS, GUIDE_ZENITH_BINS, GUIDE_AZIMUTH_BINS)

    def at(self, up, altitude) -> "GuideAtVertex":
        """The guide at scattering vertices with local zenith ``up`` and ``altitude`` (m): the
        layers around them and the sun's local frame, shared by its sample and pdf."""
        position = dr.sqrt(dr.clip(altitude / self.top, 0.0, 1.0)) * (GUIDE_LAYERS - 1)
        below = dr.minimum(mi.UInt32(position), GUIDE_LAYERS - 2)
        return GuideAtVertex(self, up, below, position - mi.Float(below))


class GuideAtVertex:
    """A :class:`ScatteredLightGuide` at vertices: ``below``, the layer just under them, and
    ``fraction``, how far they are on the way to the next one (the layer is drawn between the
    two); ``towards_sun`` and ``across``, the horizontal unit vectors the azimuths count from."""

    def __init__(self, guide, up, below, fraction):
        self.guide, self.up, self.below, self.fraction = guide, up, below, fraction
        self.towards_sun, self.across = _sun_frame(up, guide.sun_direction)

    def sample(self, u_layer, u_cell, u_azimuth):
        """A unit direction from three uniform numbers (the layer; the cell, then cos theta
        within it; phi within the cell and its sign)."""
        guide = self.guide
        layer = dr.select(u_layer < self.fraction, self.below + 1, self.below)
        offset = layer * guide.cells
        cell = dr.binary_search(0, guide.cells - 1,
                                lambda c: dr.gather(mi.Float, guide.cumulative, offset + c) <= u_cell)
        upper = dr.gather(mi.Float, guide.cumulative, offset + cell)
        lower = dr.select(cell > 0, dr.gather(mi.Float, guide.cumulative, offset + cell - 1, cell > 0), 0.0)
        within = dr.clip((u_cell - lower) / dr.maximum(upper - lower, 1e-30), 0.0, 1.0)
        zenith_bin, azimuth_bin = cell // GUIDE_AZIMUTH_BINS, cell % GUIDE_AZIMUTH_BINS
        cos_top = dr.gather(mi.Float, guide.cos_edges, zenith_bin)
        cos_theta = cos_top - within * (cos_top - dr.gather(mi.Float, guide.cos_edges, zenith_bin + 1))
        mirrored = u_azimuth < 0.5
        phi = (mi.Float(azimuth_bin) + dr.select(mirrored, 2.0 * u_azimuth, 2.0 * u_azimuth - 1.0)) * guide.azimuth_step
        sin_phi, cos_phi = dr.sincos(dr.select(mirrored, -phi, phi))
        sin_theta = dr.safe_sqrt(1.0 - cos_theta * cos_theta)
        return (sin_theta * cos_phi) * self.towards_sun + (sin_theta * sin_phi) * self.across + cos_theta * self.up

    def _cell(self, direction):
        """The cell of the unit ``direction`` in the layer below: (its index in the table, its
        zenith bin)."""
        guide = self.guide
        theta = dr.acos(dr.clip(dr.dot(direction, self.up), -1.0, 1.0))
        zenith_bin = dr.minimum(mi.UInt32(theta * (GUIDE_ZENITH_BINS / math.pi)), GUIDE_ZENITH_BINS - 1)
        phi = dr.atan2(dr.abs(dr.dot(direction, self.across)), dr.dot(direction, self.towards_sun))
        azimuth_bin = dr.minimum(mi.UInt32(phi / guide.azimuth_step), GUIDE_AZIMUTH_BINS - 1)
        return self.below * guide.cells + zenith_bin * GUIDE_AZIMUTH_BINS + azimuth_bin, zenith_bin

    def _between_layers(self, table, index, stride):
        """A per-layer ``table``'s value at ``index`` in the layer below (``stride`` values per
        layer), interpolated between the two layers."""
        return ((1.0 - self.fraction) * dr.gather(mi.Float, table, index)
                + self.fraction * dr.gather(mi.Float, table, index + stride))

    def pdf(self, direction):
        """Density (sr^-1) with which :meth:`sample` produces the unit ``direction``."""
        cell, zenith_bin = self._cell(direction)
        return self._between_layers(self.guide.probability, cell, self.guide.cells) / (
            2.0 * dr.gather(mi.Float, self.guide.cell_solid_angle, zenith_bin))

    def radiance(self, direction, multiple_only: bool = False):
        """The radiance the table expects to arrive from the unit ``direction`` (W m^-2 sr^-1
        nm^-1, the mean over its channels): a cell's L1 + Lm, or Lm alone with
        ``multiple_only`` (only once the pilot's is added), plus ``GUIDE_FLOOR`` of its layer's
        mean, so that only a layer with no light at all reads 0. Between the two layers."""
        table, layer_mean = self.guide.multiple if multiple_only else self.guide.radiance
        cell, _ = self._cell(direction)
        return (self._between_layers(table, cell, self.guide.cells)
                + GUIDE_FLOOR * self._between_layers(layer_mean, self.below, 1))
