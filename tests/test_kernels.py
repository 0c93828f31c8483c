"""Cutting a render into kernels (:mod:`skyref.plugins.kernels`): the cuts evaluate what they are
given outside symbolic code and nothing inside it, and a render cut into kernels launches more
of them and is the same to the last bit as one left whole."""

import drjit as dr
import mitsuba
import numpy as np

from skyref.plugins.kernels import cut_kernel


@dr.syntax
def count_up(total):
    """``total`` + 3 by a symbolic loop that asks for a cut at each step (an evaluation inside
    the loop would raise). Defined here: ``dr.syntax`` rewrites a function without its closure."""
    i = mitsuba.UInt32(0)
    while i < 3:
        total = total + 1.0
        cut_kernel(total)
        i += 1
    return total


def test_a_cut_evaluates_outside_symbolic_code_and_waits_inside_it(mi):
    x = mi.Float(1.0, 2.0) * 3.0
    assert x.state == dr.VarState.Unevaluated
    cut_kernel([x], None)
    assert x.state == dr.VarState.Evaluated

    assert np.array_equal(count_up(mi.Float(0.0, 10.0)).numpy(), [3.0, 13.0])


def test_a_render_cut_into_kernels_is_the_render_left_whole(mi, monkeypatch):
    """Line integral, a low sun (its grazing panels): whole paths (the camera segment's quadrature
    and the path's later segments, as for pixels sampled over their area), and single scattering
    and orders >= 2 traced apart (fixed directions). The same radiance bit for bit with every cut
    disabled, from fewer kernels."""
    import skyref.atmosphere as atm
    import skyref.plugins.integrator as integrator_module
    import skyref.plugins.line_integral as line_integral_module
    from skyref.render import build_integrator
    from skyref.scene import RenderSettings, Scene, Sun, direction_from_angles

    views = np.array([direction_from_angles(z, a) for z, a in [(0.0, 0.0), (60.0, 90.0), (89.5, 180.0)]],
                     dtype=np.float32)
    table = mi.Vector3f(*(mi.Float(views[:, i]) for i in range(3)))
    scene = Scene(atmosphere=atm.rayleigh_only(), sun=Sun(88.0, 180.0), wavelengths=[680.0, 550.0, 440.0],
                  render=RenderSettings(estimator="line_integral"))

    def camera_rays(sampler, target):
        return mi.Point3f(0.0), dr.gather(mi.Vector3f, table, target), mi.Bool(True)

    def render():
        dr.kernel_history()                                     # clear it
        integrator = build_integrator(scene)
        whole_paths = integrator._estimate(7, len(views), 64, 1, camera_rays, False).numpy()
        apart = integrator.render_directions(views, seed=7, spp=64).numpy()
        return (whole_paths, apart), len(dr.kernel_history())

    dr.set_flag(dr.JitFlag.KernelHistory, True)
    try:
        cut, cut_kernels = render()
        monkeypatch.setattr(line_integral_module, "cut_kernel", lambda *state: None)
        monkeypatch.setattr(integrator_module, "cut_kernel", lambda *state: None)
        whole, whole_kernels = render()
    finally:
        dr.set_flag(dr.JitFlag.KernelHistory, False)
    print(f"{cut_kernels} kernels cut, {whole_kernels} whole")
    assert cut_kernels > whole_kernels
    for a, b in zip(cut, whole):
        assert np.all(np.isfinite(a)) and np.any(a > 0.0)
        assert np.array_equal(a, b)
