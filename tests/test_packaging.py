"""What pip installs: the core, the ``fit`` and ``batch`` extras, and one clear line when a code
path needs an extra that is missing."""

import subprocess
import sys
import tomllib
from pathlib import Path

import pytest
from packaging.requirements import Requirement

from skyref.errors import SkyrefSetupError
from skyref.extras import EXTRAS, require

ROOT = Path(__file__).resolve().parent.parent
PYPROJECT = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
# The distribution that installs each module the extras need (import name -> pip name, extras).
DISTRIBUTIONS = {"jax": ("jax", set()), "optimistix": ("optimistix", set()), "lineax": ("lineax", set()),
                 "dask": ("dask", {"distributed"}), "distributed": ("dask", {"distributed"}),
                 "xarray": ("xarray", set()), "zarr": ("zarr", set())}
HEAVY = ("jax", "jaxlib", "optimistix", "lineax", "equinox", "dask", "distributed", "xarray", "zarr")


def requirements(entries) -> dict:
    return {(r := Requirement(entry)).name.lower(): r for entry in entries}


def test_core_leaves_the_extras_out_and_declares_pillow():
    core = requirements(PYPROJECT["dependencies"])
    assert not {"jax", "optimistix", "lineax", "dask", "distributed", "xarray", "zarr"} & set(core)
    assert "pillow" in core                         # skyref.io.png, skyref.invert.inputs


@pytest.mark.parametrize("extra", ["fit", "batch"])
def test_extras_declare_what_require_checks(extra):
    declared = requirements(PYPROJECT["optional-dependencies"][extra])
    for module in EXTRAS[extra]:
        name, extras = DISTRIBUTIONS[module]
        assert name in declared and extras <= declared[name].extras, module


def test_run_sh_test_installs_every_extra():
    assert "pip install -q -e '.[test,fit,batch]'" in (ROOT / "run.sh").read_text()


@pytest.mark.parametrize("extra, module", [("fit", "optimistix"), ("fit", "jax"), ("batch", "distributed")])
def test_a_missing_extra_is_one_line_naming_the_pip_install(extra, module, monkeypatch):
    require(extra)                                  # everything installed here: no error
    monkeypatch.setitem(sys.modules, module, None)  # as if not installed: find_spec says None
    with pytest.raises(SkyrefSetupError) as info:
        require(extra)
    message = str(info.value)
    assert message.startswith(f"{module} not installed") and "\n" not in message
    assert message.endswith(f"pip install 'skyref[{extra}]'")


def test_entry_points_check_before_any_work(monkeypatch):
    from skyref.batch.run import connect, local_cluster, run_batch
    from skyref.fit.evaluate import throughput
    from skyref.fit.fitter import fit_table
    from skyref.fit.training import load_batch_dataset

    for name in HEAVY:
        monkeypatch.setitem(sys.modules, name, None)
    # Arguments that would fail any other way: the extra's check must come first.
    for call, extra in ((lambda: fit_table(None), "fit"), (lambda: throughput(None), "fit"),
                        (lambda: load_batch_dataset("/no/such/dataset"), "fit"), (lambda: run_batch(None), "batch"),
                        (lambda: local_cluster(0), "batch"), (lambda: connect("nowhere"), "batch")):
        with pytest.raises(SkyrefSetupError, match=rf"pip install 'skyref\[{extra}\]'"):
            call()


# Without the extras (as after a plain `pip install skyref`): every module still imports, and
# the commands that need an extra end with one line and exit status 2.
WITHOUT_EXTRAS = f"""
import importlib, pkgutil, sys
for name in {HEAVY!r}:
    sys.modules[name] = None
import skyref
from skyref.plugins import load_mitsuba
load_mitsuba()  # the plugin modules need a Mitsuba variant
for module in pkgutil.walk_packages(skyref.__path__, "skyref."):
    importlib.import_module(module.name)
from skyref.cli import main
sys.exit(main(sys.argv[1:]))
"""


@pytest.mark.parametrize("args, extra", [(["fit", "--grid", "out/no-such-batch"], "fit"),
                                         (["batch", "grids/example.toml"], "batch")])
def test_cli_without_extras(args, extra):
    result = subprocess.run([sys.executable, "-c", WITHOUT_EXTRAS, *args], capture_output=True, text=True,
                            timeout=300, cwd=ROOT)
    assert result.returncode == 2, result.stderr
    assert result.stderr.splitlines() == [f"skyref {args[0]}: error: {', '.join(EXTRAS[extra])} not installed "
                                          f"(needed by skyref's {extra} tools): pip install 'skyref[{extra}]'"]
