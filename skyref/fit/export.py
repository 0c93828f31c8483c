"""Write coefficient tables where other programs can use them, and read them back.

One set of tables (kind -> :class:`~skyref.analytic.hosek.CoefficientTable`, all of one form) is
written as:

- ``<name>.npz``: every table's arrays under the published names
  (:func:`skyref.analytic.hosek.array_names`: ``dataset320``, ``datasetRad320``,
  ``datasetXYZ1``, ...; ``perezDataset320`` ... for the Perez form), flat float64 in the published
  layout, plus ``skyref_metadata`` (a JSON string);
- ``<name>.json``: the same numbers as nested lists ``[albedo][turbidity][control point]
  [coefficient]`` per channel, with the layout, units, coefficient names and metadata spelled out;
- for the Hosek–Wilkie form, C headers in exactly the layout of the published
  ``ArHosekSkyModelData_Spectral.h``, ``ArHosekSkyModelData_CIEXYZ.h`` and
  ``ArHosekSkyModelData_RGB.h``: the same file names, array names (``datasets``, ``datasetsRad``,
  ``datasetsXYZ``, ``datasetsXYZRad``, ``datasetsRGB``, ``datasetsRGBRad``) and types
  (``double``), so the reference implementation ``ArHosekSkyModel.c`` compiles against them
  unchanged. The spectral header also carries the published solar radiance function
  (``solarDatasets``, ``limbDarkeningDatasets``), which skyref does not refit, under its BSD
  license. Numbers are written with Python's shortest round-trip representation: the C compiler
  reads back exactly the float64 values.

:func:`read_tables` reads ``.npz`` (ours or the published one) and ``.json`` files.

References
----------
L. Hosek, A. Wilkie, "An Analytic Model for Full Spectral Sky-Dome Radiance", ACM TOG 31(4), 2012 (the
coefficient layout of its reference implementation, ``ArHosekSkyModel.c`` and ``ArHosekSkyModelData_*.h``).
"""

from __future__ import annotations

import datetime
import json
import os

import numpy as np

from skyref import __version__
from skyref.analytic.hosek import (ALBEDOS, CHANNELS, FORMS, TURBIDITIES, UNITS, CoefficientTable, array_names,
                                   published_arrays)
from skyref.errors import ParameterError
from skyref.io.atomic import atomic_path, atomic_write

__all__ = ["HEADER_NAMES", "POINTER_ARRAYS", "c_header", "default_metadata", "read_spectral_table", "read_tables", "write_c_headers",
           "write_json", "write_npz", "write_tables"]

#: Published header file name of each kind of table.
HEADER_NAMES = {"spectral": "ArHosekSkyModelData_Spectral.h", "xyz": "ArHosekSkyModelData_CIEXYZ.h",
                "rgb": "ArHosekSkyModelData_RGB.h"}
#: Name of each kind's pointer arrays in the published headers (shape, radiance).
POINTER_ARRAYS = {"spectral": ("datasets", "datasetsRad"), "xyz": ("datasetsXYZ", "datasetsXYZRad"),
                  "rgb": ("datasetsRGB", "datasetsRGBRad")}
_METADATA_KEY = "skyref_metadata"
_LAYOUT = ("per channel: coefficients[albedo 2: 0, 1][turbidity 10: 1..10][Bezier control point 6][coefficient], "
           "radiances[albedo 2][turbidity 10][Bezier control point 6]; control points over "
           "x = (solar elevation / (pi/2))^(1/3); radiance = radiances(x) * F(theta, gamma; coefficients(x))")
_HOSEK_LICENSE = """Copyright (c) 2012 - 2013, Lukas Hosek and Alexander Wilkie
All rights reserved.

Redistribution and use in source and binary forms, with or without
modification, are permitted provided that the following conditions are met:

    * Redistributions of source code must retain the above copyright
      notice, this list of conditions and the following disclaimer.
    * Redistributions in binary form must reproduce the above copyright
      notice, this list of conditions and the following disclaimer in the
      documentation and/or other materials provided with the distribution.
    * None of the names of the contributors may be used to endorse or promote
      products derived from this software without specific prior written
      permission.

THIS SOFTWARE IS PROVIDED BY THE COPYRIGHT HOLDERS AND CONTRIBUTORS "AS IS" AND
ANY EXPRESS OR IMPLIED WARRANTIES, INCLUDING, BUT NOT LIMITED TO, THE IMPLIED
WARRANTIES OF MERCHANTABILITY AND FITNESS FOR A PARTICULAR PURPOSE ARE
DISCLAIMED. IN NO EVENT SHALL THE COPYRIGHT HOLDERS BE LIABLE FOR ANY
DIRECT, INDIRECT, INCIDENTAL, SPECIAL, EXEMPLARY, OR CONSEQUENTIAL DAMAGES
(INCLUDING, BUT NOT LIMITED TO, PROCUREMENT OF SUBSTITUTE GOODS OR SERVICES;
LOSS OF USE, DATA, OR PROFITS; OR BUSINESS INTERRUPTION) HOWEVER CAUSED AND
ON ANY THEORY OF LIABILITY, WHETHER IN CONTRACT, STRICT LIABILITY, OR TORT
(INCLUDING NEGLIGENCE OR OTHERWISE) ARISING IN ANY WAY OUT OF THE USE OF THIS
SOFTWARE, EVEN IF ADVISED OF THE POSSIBILITY OF SUCH DAMAGE."""


def _check_tables(tables: dict) -> str:
    """The common form of ``tables`` (kind -> table); raise if empty, mixed or mislabelled."""
    if not tables:
        raise ParameterError("tables", {}, "at least one table", "nothing to write")
    forms = {table.form for table in tables.values()}
    if len(forms) > 1 or any(kind != table.kind for kind, table in tables.items()):
        raise ParameterError("tables", {k: f"{t.form} {t.kind}" for k, t in tables.items()},
                             "tables of one form, each under its own kind", "mixed or mislabelled")
    return forms.pop()


def default_metadata(form: str) -> dict:
    return {"format": "skyref analytic sky coefficients", "format_version": 1, "form": form,
            "skyref_version": __version__,
            "created": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"),
            "layout": _LAYOUT, "coefficient_names": list(FORMS[form][0])}


def write_npz(tables: dict, path, metadata: dict | None = None) -> str:
    """Write ``tables`` (kind -> table, one form) to ``path`` (``.npz``, atomically)."""
    form = _check_tables(tables)
    arrays = {}
    for table in tables.values():
        arrays.update(table.arrays())
    arrays[_METADATA_KEY] = np.array(json.dumps(dict(default_metadata(form), **(metadata or {}))))
    with atomic_path(path) as tmp:
        np.savez(tmp, **arrays)
    return os.fspath(path)


def write_json(tables: dict, path, metadata: dict | None = None) -> str:
    """Write ``tables`` to ``path`` (``.json``, atomically): nested lists per channel."""
    form = _check_tables(tables)
    document = dict(default_metadata(form), **(metadata or {}))
    document["tables"] = {
        kind: {"unit": UNITS[kind], "source": table.source, "channels": list(table.channels),
               "coefficients": {c: table.coefficients[i].tolist() for i, c in enumerate(table.channels)},
               "radiances": {c: table.radiances[i].tolist() for i, c in enumerate(table.channels)}}
        for kind, table in tables.items()}
    with atomic_write(path) as f:
        json.dump(document, f, indent=1)
    return os.fspath(path)


def _c_array(name: str, values, rows_per_comment: int | None) -> str:
    """``double name[] = { ... };`` with a ``// albedo a, turbidity t`` comment every
    ``rows_per_comment`` values (the published headers' style)."""
    lines = [f"double {name}[] =", "{"]
    for i, value in enumerate(np.asarray(values, dtype=np.float64).ravel()):
        if rows_per_comment and i % rows_per_comment == 0:
            block = i // rows_per_comment
            lines.append(f"\t// albedo {ALBEDOS[block // len(TURBIDITIES)]:g}, "
                         f"turbidity {TURBIDITIES[block % len(TURBIDITIES)]:g}")
        lines.append(f"\t{float(value)!r},")
    lines.append("};")
    return "\n".join(lines)


def _c_pointers(name: str, members) -> str:
    return f"double* {name}[] =\n{{\n" + ",\n".join(f"\t{m}" for m in members) + "\n};"


def c_header(table: CoefficientTable, note: str = "") -> str:
    """The published ``ArHosekSkyModelData_*.h`` of ``table``'s kind, with ``table``'s numbers
    (Hosek–Wilkie form only). ``note``: text for the header's opening comment."""
    if table.form != "hosek":
        raise ParameterError("form", table.form, "'hosek'", "only Hosek–Wilkie tables have a C header")
    per_block = len(table.coefficient_names) * table.coefficients.shape[3]
    shape_names, radiance_names, parts = [], [], []
    for index in range(len(table.channels)):
        shape_name, radiance_name = array_names("hosek", table.kind, index)
        shape_names.append(shape_name)
        radiance_names.append(radiance_name)
        parts.append(_c_array(shape_name, table.coefficients[index], per_block))
        parts.append(_c_array(radiance_name, table.radiances[index], table.coefficients.shape[3]))
    shape_pointers, radiance_pointers = POINTER_ARRAYS[table.kind]
    parts += [_c_pointers(shape_pointers, shape_names), _c_pointers(radiance_pointers, radiance_names)]
    if table.kind == "spectral":
        published = published_arrays()
        for prefix, pointers in (("solarDataset", "solarDatasets"), ("limbDarkeningDataset", "limbDarkeningDatasets")):
            names = [f"{prefix}{channel}" for channel in CHANNELS["spectral"]]
            parts += [_c_array(name, published[name], None) for name in names]
            parts.append(_c_pointers(pointers, names))
    comment = (f"/*\n{HEADER_NAMES[table.kind]}: Hosek-Wilkie sky model coefficients ({table.kind}), written by "
               f"skyref {__version__}.\nSource: {table.source}\n" + (f"{note}\n" if note else "") +
               "Layout, names and types are those of the published header (version 1.4a), so that\n"
               "ArHosekSkyModel.c compiles against this file unchanged:\n"
               "  <dataset>[albedo 2][turbidity 10][control point 6][coefficient 9: A B C D E F G I H]\n"
               f"  <datasetRad>[albedo 2][turbidity 10][control point 6], {table.unit}\n"
               "Any values that skyref did not fit, and the solar radiance function of the spectral\n"
               "header, are those of the published model, under this license:\n\n"
               f"{_HOSEK_LICENSE}\n*/")
    return comment + "\n\n" + "\n\n".join(parts) + "\n"


def write_c_headers(tables: dict, directory, notes: dict | None = None) -> list[str]:
    """Write the C header of every Hosek–Wilkie table (kind -> table) into ``directory``;
    ``notes``: kind -> text for that header's opening comment. Returns the paths."""
    paths = []
    for kind, table in tables.items():
        path = os.path.join(os.fspath(directory), HEADER_NAMES[kind])
        with atomic_write(path) as f:
            f.write(c_header(table, (notes or {}).get(kind, "")))
        paths.append(path)
    return paths


def write_tables(tables: dict, directory, name: str, metadata: dict | None = None,
                 notes: dict | None = None) -> list[str]:
    """Write ``<name>.npz``, ``<name>.json`` and, for the Hosek–Wilkie form, the C headers into
    ``directory`` (created if needed). Returns the paths written."""
    form = _check_tables(tables)
    os.makedirs(os.fspath(directory), exist_ok=True)
    paths = [write_npz(tables, os.path.join(directory, f"{name}.npz"), metadata),
             write_json(tables, os.path.join(directory, f"{name}.json"), metadata)]
    if form == "hosek":
        paths += write_c_headers(tables, directory, notes)
    return paths


def read_spectral_table(path, parameter: str = "coefficients"):
    """The spectral :class:`CoefficientTable` of a coefficient file (:func:`read_tables`), or a
    ParameterError naming ``parameter`` if the file has none."""
    tables, _ = read_tables(path)
    if "spectral" not in tables:
        raise ParameterError(parameter, os.fspath(path), "a coefficient file with a spectral table", "no spectral table")
    return tables["spectral"]


def read_tables(path) -> tuple[dict, dict]:
    """Read a ``.npz`` (written by :func:`write_tables`, or the published data) or ``.json``
    file: returns (kind -> :class:`CoefficientTable`, metadata)."""
    path = os.fspath(path)
    if not os.path.isfile(path):
        raise ParameterError("coefficients", path, "an existing .npz or .json file", "file not found")
    if path.endswith(".json"):
        with open(path) as f:
            document = json.load(f)
        form = document.get("form")
        tables = {}
        for kind, entry in document.get("tables", {}).items():
            channels = CHANNELS.get(kind, ())
            tables[kind] = CoefficientTable(form, kind, np.array([entry["coefficients"][c] for c in channels]),
                                            np.array([entry["radiances"][c] for c in channels]), entry.get("source", ""))
        metadata = {k: v for k, v in document.items() if k != "tables"}
    elif path.endswith(".npz"):
        with np.load(path) as data:
            arrays = {name: data[name] for name in data.files}
        metadata = json.loads(str(arrays.pop(_METADATA_KEY))) if _METADATA_KEY in arrays else {}
        tables = {}
        for form in FORMS:
            for kind in CHANNELS:
                if all(name in arrays for name in array_names(form, kind, 0)):
                    tables[kind] = CoefficientTable.from_arrays(arrays, form, kind, source=metadata.get("source", path))
    else:
        raise ParameterError("coefficients", path, "a file ending in .npz or .json", "unknown format")
    if not tables:
        raise ParameterError("coefficients", path, "coefficient tables in the published layout", "none found")
    return tables, metadata
