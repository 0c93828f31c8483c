#!/usr/bin/env bash
# A site-packages for skyref on a GPU machine that has CUDA and Python 3.12 but cannot reach a
# package index: the wheels of skyref's dependencies that such a machine's image lacks (NumPy,
# SciPy, pandas, xarray, Matplotlib, Pillow, JAX, optimistix, lineax, pytest and hypothesis are
# assumed there), at the versions of this checkout's .venv, for CPython 3.12 on manylinux
# x86-64, unpacked and slimmed (only the Mitsuba variants skyref renders in, no C headers, no
# coverage reports, of pvlib's data only the ASTM G173 solar spectrum) into one archive of about
# 41 MB to carry there. Checked on 2026-12-04 in a Python 3.12 environment holding only those:
# 205 tests (EXR, batch on dask, plugins, sensors, objects, time-lapse through pvlib, Hosek, the
# fit through JAX) passed in llvm_ad_rgb.
#
# Usage, here (needs the package index):  bash benchmarks/gpu_bundle.sh [ARCHIVE]
#   (default .gpu/site-py312.tar.xz; add /.gpu/ to .git/info/exclude to keep it out of git)
# There:  tar -C /tmp -xJf .gpu/site-py312.tar.xz && export PYTHONPATH=/tmp/site-py312:$PWD
#         bash benchmarks/gpu_check.sh
set -euo pipefail
cd "$(dirname "$0")/.."
ARCHIVE=${1:-.gpu/site-py312.tar.xz}
PYTHON=${PYTHON:-$( [ -x .venv/bin/python ] && echo .venv/bin/python || echo python3 )}
PACKAGES="mitsuba drjit OpenEXR colour-science pvlib zarr numcodecs donfig dask distributed tomli_w
          nanodisort miepython pytz tzdata locket tblib tornado zict partd google-crc32c nanobind-backend"

work=$(mktemp -d)
tmp="$ARCHIVE.partial"
trap 'rm -rf "$work" "$tmp"' EXIT
site="$work/site-py312"
pins=()
for name in $PACKAGES; do
    version=$("$PYTHON" -m pip show "$name" 2>/dev/null | sed -n 's/^Version: //p')
    [ -n "$version" ] || { echo "gpu_bundle: $name is not installed in $PYTHON's environment (bash run.sh setup)" >&2; exit 2; }
    pins+=("$name==$version")
done
platforms=()
for p in manylinux_2_39 manylinux_2_35 manylinux_2_34 manylinux_2_31 manylinux_2_28 manylinux_2_27 manylinux_2_24 \
         manylinux_2_17 manylinux2014 manylinux1; do
    platforms+=(--platform "${p}_x86_64")
done
"$PYTHON" -m pip install -q --no-deps --no-compile --only-binary=:all: --python-version 3.12 --implementation cp \
    "${platforms[@]}" --target "$site" "${pins[@]}"

# Slimming: what skyref never loads (variants, and plugins that no scene, test or benchmark of
# skyref names).
for plugin in ellipsoids ellipsoidsmesh volpathmis bsplinecurve linearcurve sdfgrid sunsky timed_sunsky ptracer \
              principled principledthin roughplastic roughconductor roughdielectric pplastic hair measured_polarized \
              polarizer retarder; do
    rm -f "$site/mitsuba/plugins/$plugin.so"
done
find "$site/mitsuba" -maxdepth 1 \( -name '*_mono*' -o -name '*_polarized*' -o -name 'scalar_*' \) -exec rm -rf {} +
rm -rf "$site/mitsuba/include" "$site/mitsuba/cmake" "$site/drjit/include" "$site/drjit/cmake" "$site/bin"
find "$site" -type d \( -name htmlcov -o -name __pycache__ \) -prune -exec rm -rf {} +
find "$site/pvlib/data" -type f ! -name 'ASTMG173.csv' -delete

mkdir -p "$(dirname "$ARCHIVE")"
tar -C "$work" -cJf "$tmp" site-py312
mv "$tmp" "$ARCHIVE"
echo "gpu_bundle: $ARCHIVE ($(du -h "$ARCHIVE" | cut -f1)): ${pins[*]}"
