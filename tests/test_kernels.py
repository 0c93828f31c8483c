"""Cutting a render into kernels (:mod:`skyref.plugins.kernels`): the cuts evaluate what they are
given outside symbolic code and nothing inside it, and a render cut into kernels launches more
of them and is the same to the last bit as one left whole; block sums give the closed-form sums
and forward derivatives, the tangents of all the values from one kernel."""

import drjit as dr
import mitsuba
import numpy as np

from skyref.plugins.kernels import cut_kernel, sum_blocks


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
    disabled, from fewer kernels. One wavelength: the uncut kernels are the longest to compile."""
    import skyref.atmosphere as atm
    import skyref.plugins.integrator as integrator_module
    import skyref.plugins.line_integral as line_integral_module
    from skyref.render import build_integrator
    from skyref.scene import RenderSettings, Scene, Sun, direction_from_angles

    views = np.array([direction_from_angles(z, a) for z, a in [(0.0, 0.0), (60.0, 90.0), (89.5, 180.0)]],
                     dtype=np.float32)
    table = mi.Vector3f(*(mi.Float(views[:, i]) for i in range(3)))
    scene = Scene(atmosphere=atm.rayleigh_only(), sun=Sun(88.0, 180.0), wavelengths=[550.0],
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


def test_block_sums_and_their_forward_derivatives_evaluate_all_values_in_one_kernel(mi):
    """Three values of x over 8 lanes (l = 0..7), summed in blocks of 4 into slots (block b,
    value i) -> 3 b + i: sums of l x, l x^2 and sin(l x), and their derivatives in x, at x = 2.
    The tangents of the three must come from a single kernel as wide as the lanes (summed one by
    one, Dr.Jit's own derivative of a block sum evaluates each tangent in a kernel of its own)."""
    dr.set_flag(dr.JitFlag.KernelHistory, True)                 # (set later, it records nothing)
    try:
        x = mi.Float(2.0)
        dr.enable_grad(x)
        lane = dr.arange(mi.Float, 8)
        values = [lane * x, lane * x * x, dr.sin(lane * x)]
        slots = [dr.arange(mi.UInt32, 2) * 3 + i for i in range(3)]
        sums = sum_blocks(values, 4, slots, 6)
        dr.kernel_history()                                     # clear it
        dr.forward(x)
        tangents = dr.grad(sums).numpy()
        launches = dr.kernel_history()
    finally:
        dr.set_flag(dr.JitFlag.KernelHistory, False)

    blocks = [np.arange(4.0), np.arange(4.0, 8.0)]
    expected = [[b.sum() * 2.0, b.sum() * 4.0, np.sin(2.0 * b).sum()] for b in blocks]
    expected_tangents = [[b.sum(), b.sum() * 4.0, (b * np.cos(2.0 * b)).sum()] for b in blocks]
    assert np.allclose(sums.numpy(), np.ravel(expected), rtol=1e-6, atol=1e-6)
    assert np.allclose(tangents, np.ravel(expected_tangents), rtol=1e-6, atol=1e-6)
    lane_kernels = [k for k in launches if k["type"] == dr.KernelType.JIT and k["size"] == 8]
    assert len(lane_kernels) == 1
