"""The outcome of an inversion, and how it is written: ``result.json`` (estimates, uncertainties,
identifiability with its evidence, residuals, convergence history, which model produced each
number), ``convergence.png``, ``residuals.png`` (observed, fitted, residual maps), ``fitted.exr``
(the fitted sky, spectral, as ``skyref render`` writes it) and ``residual.exr`` (the log residual
per channel).

Residual maps are log(s m) - log y per pixel and channel: model m from the ground truth at the
estimate over the whole image (``map_spp`` samples per pixel; their Monte Carlo error is reported
beside them), exposure s, observed y; about the relative error for small values. NaN where a
pixel is not used.

matplotlib and :mod:`skyref.color` are imported inside the plotting methods: selecting matplotlib's
Agg backend is a side effect, made only when plots are written, and colour-science takes about 2.5 s
to import while ``skyref --help`` imports this module (through :mod:`skyref.invert`).
"""

from __future__ import annotations

import dataclasses
import json
import math
import os
import warnings
from dataclasses import dataclass

import numpy as np
import OpenEXR

import skyref
from skyref.atmosphere import turbidity
from skyref.invert.parameters import UNKNOWNS
from skyref.io.atomic import atomic_path, atomic_write
from skyref.io.exr import write_sky_exr
from skyref.io.json_numpy import numpy_default

__all__ = ["PROVENANCE", "InversionResult"]

#: Which model produced which number (the JSON's "provenance").
PROVENANCE = {
    "estimates": "ground-truth path tracer (skyref 'atmosphere' integrator): Levenberg-Marquardt iterations, then "
                 "one Gauss-Newton step with the model and a forward-mode AD Jacobian at final_spp (the Jacobian "
                 "averaged with those of the last iterations)",
    "uncertainties": "cluster-robust curvature of the same final step (std); plain curvature in std_curvature",
    "identifiability": "posterior vs prior std and sensitivities from the same final step's AD Jacobian",
    "residual_map": "ground-truth path tracer at the estimate, every image pixel, map_spp samples per pixel",
    "surrogate": "none: no cheaper model was used at any stage",
}


@dataclass
class InversionResult:
    """Everything an inversion produced (see :func:`skyref.invert.invert`). ``covariance`` is over
    ``names`` (the free unknowns, then ``log_exposure`` for a relative image)."""

    observation: object
    parameters: object
    settings: object
    values: dict
    covariance: np.ndarray
    covariance_curvature: np.ndarray
    names: list
    log_exposure: float | None
    identifiability: list
    history: list
    converged: bool
    rows: np.ndarray
    cols: np.ndarray
    footprint: int
    final_rms_log_residual: float
    fitted_sky: object
    fit_time_s: float
    total_time_s: float

    # --- numbers ------------------------------------------------------------------------------

    @property
    def std(self) -> dict:
        """name -> standard deviation of each free unknown (cluster-robust)."""
        return {n: float(math.sqrt(self.covariance[k, k])) for k, n in enumerate(self.parameters.free)}

    @property
    def exposure(self) -> float | None:
        return None if self.log_exposure is None else math.exp(self.log_exposure)

    def residual_map(self) -> np.ndarray:
        """(H, W, C) log(s m) - log y over the image, NaN where pixels are not used."""
        obs = self.observation
        model = obs.to_channels(self.fitted_sky.radiance)
        with np.errstate(divide="ignore", invalid="ignore"):
            residual = np.log(model) + (self.log_exposure or 0.0) - np.log(obs.values)
        return np.where(obs.mask[..., None], residual, np.nan)

    def _residual_stats(self, residual) -> dict:
        finite = residual[np.all(np.isfinite(residual), axis=-1)]
        return {"pixels": int(finite.shape[0]), "rms_log": float(np.sqrt(np.mean(finite ** 2))),
                "mean_log": float(np.mean(finite)),
                "rms_log_per_channel": dict(zip(self.observation.channel_names,
                                                np.sqrt(np.mean(finite ** 2, axis=0)).tolist()))}

    def to_dict(self) -> dict:
        """The JSON document (see the module docstring)."""
        obs, params = self.observation, self.parameters
        std = self.std
        curvature_std = np.sqrt(np.diag(self.covariance_curvature))
        estimates = {}
        for name in params.present:
            unknown = UNKNOWNS[name]
            entry = {"value": self.values[name], "unit": unknown.unit, "description": unknown.description,
                     "free": name in params.free}
            if name in params.free:
                k = params.free.index(name)
                lo, hi = params.bounds[name]
                entry.update(std=std[name], std_curvature=float(curvature_std[k]), initial=params.values[name],
                             bounds=[lo, hi], model=PROVENANCE["estimates"], **self.identifiability[k])
            else:
                entry["model"] = "fixed (not fitted)"
            estimates[name] = entry
        fitted_atmosphere = params.atmosphere_at(self.values)
        aerosol = next(c for c in fitted_atmosphere.constituents if c.kind == "aerosol")
        std_all = np.sqrt(np.diag(self.covariance))
        residual = self.residual_map()
        fitted = residual[self.rows, self.cols]
        map_error = self.fitted_sky.relative_error()[obs.mask]
        return {
            "skyref_version": skyref.__version__,
            "image": obs.image.source, "channels": obs.channels, "channel_names": obs.channel_names,
            "model_wavelengths_nm": obs.wavelengths_nm.tolist(), "absolute": obs.absolute,
            "camera": obs.camera.to_dict(), "sun": {"zenith_deg": obs.sun.zenith_deg, "azimuth_deg": obs.sun.azimuth_deg},
            "observer": obs.observer.to_dict(), "base_atmosphere": params.atmosphere.name or "(custom)",
            "provenance": PROVENANCE,
            "estimates": estimates,
            "derived": {"angstrom_beta": aerosol.angstrom_beta, "turbidity_550": turbidity(fitted_atmosphere)},
            "exposure": None if self.log_exposure is None else {
                "value": self.exposure, "std_log": float(std_all[-1]),
                "meaning": "observed value = exposure x radiance (W m^-2 sr^-1 nm^-1, or its XYZ)"},
            "correlation": {"names": self.names,
                            "matrix": (self.covariance / np.outer(std_all, std_all)).round(4).tolist()},
            "fit": {"converged": self.converged, "iterations": len(self.history) - 1,
                    "pixels_fitted": int(self.rows.size), "pixels_usable": int(obs.mask.sum()),
                    "footprint_directions_per_pixel": self.footprint ** 2,
                    "sigma_log": self.final_rms_log_residual, "fit_time_s": self.fit_time_s,
                    "total_time_s": self.total_time_s},
            "residuals": {"fitted_pixels": self._residual_stats(fitted),
                          "all_usable_pixels": self._residual_stats(residual[obs.mask]),
                          "model": PROVENANCE["residual_map"], "map_spp": int(self.fitted_sky.metadata["spp"]),
                          "map_relative_mc_error_median": float(np.nanmedian(map_error))},
            "history": self.history,
            "notes": obs.notes,
            "settings": dataclasses.asdict(self.settings),
        }

    def summary_lines(self) -> list[str]:
        """A short human-readable table of the estimates."""
        lines = [f"{'unknown':<16}{'estimate':>12}{'std':>11}   identifiable"]
        for k, name in enumerate(self.parameters.free):
            flag = self.identifiability[k]
            verdict = "yes" if flag["identifiable"] else (
                "NO: " + ("at a bound; " if flag["at_bound"] else "") +
                f"posterior std {flag['posterior_to_prior_std']:.2f} of the prior's; "
                f"sensitivity {flag['sensitivity_rms_log_per_prior_std']:.2g} vs noise {flag['noise_rms_log']:.2g}; "
                f"correlated with {flag['most_correlated_with']} ({flag['correlation']:+.2f})")
            lines.append(f"{name:<16}{self.values[name]:>12.4g}{self.std[name]:>11.3g}   {verdict}")
        if self.log_exposure is not None:
            lines.append(f"{'exposure':<16}{self.exposure:>12.4g}{self.exposure * math.sqrt(self.covariance[-1, -1]):>11.3g}")
        return lines

    # --- files --------------------------------------------------------------------------------

    def write(self, directory) -> list[str]:
        """Write result.json, convergence.png, residuals.png, fitted.exr and residual.exr into
        ``directory``; returns their paths."""
        os.makedirs(directory, exist_ok=True)
        paths = {name: os.path.join(directory, name) for name in
                 ("result.json", "convergence.png", "residuals.png", "fitted.exr", "residual.exr")}
        with atomic_write(paths["result.json"]) as f:
            json.dump(self.to_dict(), f, indent=1, default=numpy_default)
        self.plot_convergence(paths["convergence.png"])
        self.plot_residuals(paths["residuals.png"])
        write_sky_exr(self.fitted_sky, paths["fitted.exr"])
        self._write_residual_exr(paths["residual.exr"])
        return list(paths.values())

    def _write_residual_exr(self, path):
        residual = self.residual_map().astype(np.float32)
        channels = {f"residual.{name.replace(' ', '')}": np.ascontiguousarray(residual[..., c])
                    for c, name in enumerate(self.observation.channel_names)}
        header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage,
                  "skyref.meaning": "log(exposure x model) - log(observed); NaN where unused"}
        with atomic_path(path) as tmp, OpenEXR.File(header, channels) as exr:
            exr.write(tmp)

    def plot_convergence(self, path):
        """Each free unknown and the rms log residual per iteration (the last point is the final
        Gauss–Newton step, with its ±1 std)."""
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        free = self.parameters.free
        panels = len(free) + 1
        columns = min(3, panels)
        rows = math.ceil(panels / columns)
        fig, axes = plt.subplots(rows, columns, figsize=(4 * columns, 2.8 * rows), squeeze=False)
        steps = np.arange(len(self.history))
        for ax, name in zip(axes.flat, free):
            trace = [h["values"][name] for h in self.history]
            ax.plot(steps, trace, "o-", ms=3)
            ax.errorbar(steps[-1], trace[-1], yerr=self.std[name], fmt="s", color="C3", capsize=3)
            ax.set_title(name, fontsize=9)
            ax.set_xlabel("iteration")
        ax = axes.flat[len(free)]
        ax.semilogy(steps, [h["rms_log_residual"] for h in self.history], "o-", ms=3, label="rms log residual")
        ax.set_xlabel("iteration")
        ax.set_title("rms log residual", fontsize=9)
        twin = ax.twinx()
        twin.semilogy(steps, [h["spp"] for h in self.history], "x:", color="C2")
        twin.set_ylabel("samples per pixel", color="C2")
        for ax in list(axes.flat)[panels:]:
            ax.axis("off")
        fig.tight_layout()
        with atomic_path(path) as tmp:
            fig.savefig(tmp, dpi=110, format="png")
        plt.close(fig)

    def plot_residuals(self, path):
        """Observed and fitted images (same tone mapping), the mean log residual over channels
        (brightness) and its spread over channels (colour), fitted pixels marked."""
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        from skyref.color import default_exposure, spectral_to_linear_srgb, tonemap_srgb8

        obs = self.observation
        observed = obs.image.linear_srgb()
        fitted = spectral_to_linear_srgb(self.fitted_sky.radiance, self.fitted_sky.wavelengths_nm) * (self.exposure or 1.0)
        exposure = default_exposure(observed)
        residual = self.residual_map()
        with warnings.catch_warnings():   # unused pixels are all-NaN
            warnings.simplefilter("ignore", RuntimeWarning)
            brightness = 100.0 * np.nanmean(residual, axis=-1)
            colour = 100.0 * np.nanstd(residual, axis=-1)
        limit = float(np.nanpercentile(np.abs(brightness), 98)) if np.isfinite(brightness).any() else 1.0
        fig, axes = plt.subplots(2, 2, figsize=(10, 10 * obs.camera.height / obs.camera.width + 1.2))
        panels = [(tonemap_srgb8(observed, exposure), "observed", {}),
                  (tonemap_srgb8(fitted, exposure), "fitted (ground truth at the estimate)", {}),
                  (brightness, "mean log residual over channels, % (model - observed)",
                   {"cmap": "RdBu_r", "vmin": -limit, "vmax": limit}),
                  (colour, "spread of log residual over channels, %", {"cmap": "magma"})]
        for ax, (image, title, style) in zip(axes.flat, panels):
            shown = ax.imshow(image, interpolation="nearest", **style)
            if style:
                fig.colorbar(shown, ax=ax, fraction=0.046)
                ax.plot(self.cols, self.rows, ".", ms=1.5, color="k", alpha=0.4)
            ax.set_title(title, fontsize=9)
            ax.set_xticks([])
            ax.set_yticks([])
        fig.tight_layout()
        with atomic_path(path) as tmp:
            fig.savefig(tmp, dpi=110, format="png")
        plt.close(fig)

