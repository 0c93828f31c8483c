"""skyref's Mitsuba plugins are registered by importing skyref.plugins, in either import order
and for variants set later; the libLLVM rule holds; the ``atmosphere`` integrator uses a Mitsuba
scene's shapes or refuses them. Each registration case runs in a fresh Python process."""

import os
import subprocess
import sys
import textwrap

import numpy as np
import pytest

BROKEN_LIBLLVM = "/usr/lib/x86_64-linux-gnu/libLLVM-15.so.1"


def run(code: str, **env) -> subprocess.CompletedProcess:
    """Run ``code`` in a fresh interpreter, without a DRJIT_LIBLLVM_PATH unless given."""
    environment = {k: v for k, v in os.environ.items() if k != "DRJIT_LIBLLVM_PATH"}
    environment.update(env)
    return subprocess.run([sys.executable, "-c", textwrap.dedent(code)], capture_output=True, text=True,
                          env=environment, timeout=600)


def setup_error(setup: str, statement: str, **env) -> str:
    """The message of the SkyrefSetupError that ``statement`` raises after ``setup`` in a fresh
    interpreter (the test fails if it raises none, or anything else)."""
    result = run(textwrap.dedent(setup) + textwrap.dedent(f"""
        from skyref.errors import SkyrefSetupError
        try:
            {statement}
        except SkyrefSetupError as error:
            print(error)
        else:
            raise SystemExit("no error")
    """), **env)
    assert result.returncode == 0, result.stderr
    return result.stdout


#: Appended to the scripts below (same indentation): both kinds of plugin load.
LOADS = """
        assert type(mi.load_dict({"type": "atmosphere"})).__name__ == "AtmosphereIntegrator"
        assert mi.load_dict({"type": "skyref_sky", "width": 8}).class_name() == "EnvironmentMapEmitter"
"""


def test_import_does_not_load_mitsuba():
    """Importing the package keeps Mitsuba and Dr.Jit (~0.4 s) off ``skyref --help``."""
    result = run("""
        import sys
        import skyref.plugins
        assert "mitsuba" not in sys.modules and "drjit" not in sys.modules
    """)
    assert result.returncode == 0, result.stderr


def test_skyref_first_then_mitsuba():
    """``import skyref.plugins`` before Mitsuba: libLLVM is configured before Dr.Jit loads it,
    and the plugins are there once a variant is set."""
    result = run("""
        import os
        import skyref.plugins
        import mitsuba as mi
        assert os.environ["DRJIT_LIBLLVM_PATH"], "configure_libllvm did not run before drjit"
        mi.set_variant("llvm_ad_rgb")
    """ + LOADS)
    assert result.returncode == 0, result.stderr


def test_variant_set_before_import():
    """Mitsuba imported and its variant set first: the plugins are missing until skyref.plugins
    is imported, then there."""
    result = run("""
        import skyref._llvm
        skyref._llvm.configure_libllvm()
        import mitsuba as mi
        mi.set_variant("llvm_ad_rgb")
        try:
            mi.load_dict({"type": "atmosphere"})
            raise SystemExit("the atmosphere plugin exists before skyref.plugins is imported")
        except RuntimeError:
            pass
        import skyref.plugins
    """ + LOADS)
    assert result.returncode == 0, result.stderr


def test_variant_set_after_import():
    """Mitsuba imported, then skyref.plugins, then variants set: each gets the plugins."""
    result = run("""
        import skyref._llvm
        skyref._llvm.configure_libllvm()
        import mitsuba as mi
        import skyref.plugins
        mi.set_variant("llvm_ad_spectral")
        assert type(mi.load_dict({"type": "atmosphere_phase"})).__name__ == "AtmospherePhase"
        mi.set_variant("llvm_ad_rgb")
    """ + LOADS)
    assert result.returncode == 0, result.stderr


@pytest.mark.skipif(not os.path.exists(BROKEN_LIBLLVM), reason="no libLLVM 15 on this machine")
def test_broken_libllvm_is_refused():
    """Dr.Jit made to load libLLVM 15 (which crashes its kernels): registering for an LLVM
    variant stops with a SkyrefSetupError that says what to do."""
    message = setup_error("""
        import mitsuba as mi
        mi.set_variant("llvm_ad_rgb")
    """, "import skyref.plugins", DRJIT_LIBLLVM_PATH=BROKEN_LIBLLVM)
    assert "libLLVM 15" in message and "DRJIT_LIBLLVM_PATH=" in message
    assert "apt-get install libllvm19" in message


def test_no_libllvm_refuses_llvm_variants_only():
    """No working libLLVM (what configure_libllvm leaves on a machine without one): asking for
    an LLVM variant stops with a SkyrefSetupError that says what to install, before any work;
    importing the package and checking the CUDA backend still work (a GPU machine needs no
    libLLVM)."""
    from skyref._llvm import NO_LIBRARY

    message = setup_error("""
        import drjit as dr
        from skyref.plugins import load_mitsuba, supported_variants
        assert not dr.has_backend(dr.JitBackend.LLVM)
        assert not any(v.startswith("llvm") for v in supported_variants())
    """, 'load_mitsuba("llvm_ad_rgb")', DRJIT_LIBLLVM_PATH=NO_LIBRARY)
    assert "'llvm_ad_rgb'" in message and "apt-get install libllvm19" in message


#: Prints LLVM's target features after ``load_mitsuba`` and saves the radiance of 8 views of a
#: clear sky by the baseline estimator to the file PROBE_OUT names.
GATHER_PROBE = """
    import os
    import numpy as np
    from skyref._llvm import llvm_target_features
    from skyref.plugins import load_mitsuba
    load_mitsuba("llvm_ad_rgb")
    from skyref.atmosphere import bruneton2017
    from skyref.render import build_integrator
    from skyref.scene import Scene, Sun
    print(",".join(llvm_target_features()))
    integrator = build_integrator(Scene(atmosphere=bruneton2017(), sun=Sun(60.0, 180.0), wavelengths="rgb"),
                                  estimator="delta_tracking")
    zenith = np.radians(np.linspace(0.0, 89.0, 8))
    views = np.stack([np.sin(zenith), np.zeros(8), np.cos(zenith)], axis=1)
    np.save(os.environ["PROBE_OUT"], integrator.render_directions(views, seed=3, spp=256).numpy())
"""


def test_vector_gathers_are_allowed_and_change_no_value(tmp_path):
    """load_mitsuba adds +fast-gather to LLVM's target where the CPU has AVX2 and LLVM's tuning
    does not (``skyref._llvm.allow_vector_gathers``), not with SKYREF_LLVM_FAST_GATHER=0; either
    way a render gives the same radiance to the last bit (each in an empty kernel cache)."""
    results = {}
    for setting in ("0", "1"):
        out = tmp_path / f"radiance{setting}.npy"
        result = run(GATHER_PROBE, SKYREF_LLVM_FAST_GATHER=setting, DRJIT_CACHE_DIR=str(tmp_path / setting),
                     PROBE_OUT=str(out))
        assert result.returncode == 0, result.stderr
        results[setting] = (result.stdout.split()[0].split(","), np.load(out))
    tuned, allowed = results["0"][0], results["1"][0]
    if "+avx2" in tuned and "+fast-gather" not in tuned and "+prefer-no-gather" not in tuned:
        assert allowed == tuned + ["+fast-gather"]
    else:
        assert allowed == tuned
    assert np.all(results["0"][1][:, 1:].sum(axis=1) > 0.0)
    np.testing.assert_array_equal(results["0"][1], results["1"][1])


# --- shapes in a scene rendered with mi.render ------------------------------------------------

def _view_through(mi, shape=None):
    """Mean RGB of a 4x4 render looking north, 20 deg up, through a 1 deg field of view, with
    ``shape`` (a 1 m sphere 20 m away on that line) in the scene."""
    d = np.array([0.0, np.cos(np.radians(20.0)), np.sin(np.radians(20.0))])
    scene = {"type": "scene", "integrator": {"type": "atmosphere"},
             "sensor": {"type": "perspective", "fov": 1.0,
                        "to_world": mi.ScalarTransform4f().look_at(origin=[0, 0, 0], target=list(d), up=[0, 0, 1]),
                        "film": {"type": "hdrfilm", "width": 4, "height": 4},
                        "sampler": {"type": "independent", "sample_count": 16}}}
    if shape is not None:
        scene["ball"] = {"type": "sphere", "center": list(20.0 * d), "radius": 1.0, **shape}
    return np.array(mi.render(mi.load_dict(scene))).mean(axis=(0, 1))


def test_scene_shapes_are_objects(mi):
    """A black diffuse sphere filling the view leaves only the light scattered in the 19 m of
    air before it: under 0.1% of the sky behind it (the air's optical depth over 19 m is
    ~2e-4 at 440 nm)."""
    sky = _view_through(mi)
    black = _view_through(mi, {"bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.0, 0.0, 0.0]}}})
    assert np.all(sky > 0.01)
    assert np.all(black < 1e-3 * sky), black / sky


@pytest.mark.parametrize("shape, problem", [
    ({"bsdf": {"type": "conductor"}}, "shape 'ball' = 'Sphere': has a SmoothConductor BSDF"),
    ({"emitter": {"type": "area"}}, "shape 'ball' = 'Sphere': has an area emitter"),
    ({"interior": {"type": "homogeneous"}}, "shape 'ball' = 'Sphere': has a medium"),
])
def test_unsupported_shapes_are_refused(mi, shape, problem):
    with pytest.raises(RuntimeError) as error:
        _view_through(mi, shape)
    assert problem in str(error.value.__cause__)
