"""What a grid's skies still to render will cost, before rendering them (``skyref batch GRID
--forecast``).

Adaptive skies (``output.target_relative_error``) differ a hundredfold in cost: on the LUT
audit's grid a clear sky with the sun at the zenith takes seconds and a hazy one seen from 1 km
at sunset hours, so the progress bar's estimate (the mean time of the skies finished so far)
says little. Each sky still to do gets a pilot render of the views it traces, at a fixed sample
count and thrown away, from which :func:`skyref.render.forecast_render_to_error` replays its
adaptive rounds. A pilot costs what its samples cost (1024 views x 2048 samples: about 10-20
CPU s at 17 wavelengths) and a quarter of that again to time the views' cost per sample, a small
share of the sky it forecasts.
"""

from __future__ import annotations

from skyref.batch.grid import MAX_ROUNDS, Grid
from skyref.batch.store import BatchStore
from skyref.errors import ParameterError
from skyref.render import PILOT_SPP, forecast_render_to_error
from skyref.scene import Scene

__all__ = ["PILOT_SEED", "forecast_skies", "coordinates_text"]

#: Added to a sky's number for its pilot's seed: apart from the seeds of its rendering rounds
#: (:meth:`~skyref.batch.grid.Grid.seed`), though a thrown-away pilot could share them.
PILOT_SEED = 1 << 29


def forecast_skies(grid: Grid, indices=None, pilot_spp: int = PILOT_SPP, variant: str | None = None):
    """An iterator of (sky spec, :func:`~skyref.render.forecast_render_to_error`'s dict) for each sky of
    ``indices`` (default: all) that the grid's output directory does not hold finished, one at a
    time as its pilot ends. A sky rendered part-way is forecast whole. Only for a grid with a
    target (``output.target_relative_error``), checked at the call: a fixed ``output.spp`` costs
    what it says. :func:`~skyref.render.forecast_render_to_error` checks the rest before its pilot."""
    output = grid.output
    if output.target_relative_error is None:
        raise ParameterError("output.target_relative_error", None, "a target (a forecast replays the adaptive "
                             "rounds of a grid with one)", f"the grid renders a fixed output.spp = {output.spp}")
    store = BatchStore(grid)

    def forecasts():
        for index in range(len(grid)) if indices is None else indices:
            spec = grid.sky(index)
            if store.is_finished(spec.sky_id):
                continue
            scene = Scene.from_dict(spec.scene).replace(name=spec.sky_id)
            yield spec, forecast_render_to_error(scene, grid.target_relative_error(spec.coordinates), MAX_ROUNDS,
                                                 output.max_spp, pilot_spp=pilot_spp, seed=PILOT_SEED + index,
                                                 variant=variant, dynamic_range=output.dynamic_range)

    return forecasts()


def coordinates_text(coordinates: dict) -> str:
    """A sky's axis values on one line: ``atmosphere={preset=hillaire2020, turbidity=6.0},
    sun.zenith_deg=88.0``."""
    def text(value):
        if isinstance(value, dict):
            return "{" + ", ".join(f"{k}={text(v)}" for k, v in value.items()) + "}"
        return str(value)

    return ", ".join(f"{path}={text(value)}" for path, value in coordinates.items())
