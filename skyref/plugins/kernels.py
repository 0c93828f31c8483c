"""Where a render's work is cut into separate kernels, and why.

Dr.Jit traces the array operations of a render and compiles them, at each evaluation, into one
kernel (LLVM on the CPU, PTX on the GPU). The time LLVM takes grows with the *square* of a
kernel's length: on the 2-core AMD machines (``results/kernel_compile.md``), kernels of 36,600,
48,400, 78,600 and 80,600 operations took 7.5, 13.3, 34.8 and 39.6 s to compile. The line
integral's quadrature is unrolled in Python (each of a segment's 25-40 panels is some 2,000
operations), so its kernels were the longest, and cold kernel caches (every CI run) spent most of
their time compiling them. Cut into pieces of a few panels, it compiles much faster: each piece is
short, and the pieces of the middle panels are alike (the panels' bounds are inputs), so they
compile once. The cost is writing the state carried across each cut to memory and reading it
back (a few floats per panel and lane); renders took the same time (docs/design.md, "libLLVM").

A cut changes no value: each piece computes in float32 what the whole kernel computed in float32
registers (``tests/test_kernels.py`` checks a render bit for bit against one without cuts).

The opposite care goes into forward-mode derivatives: :func:`sum_blocks` evaluates the tangents
of all of a launch's outputs in one kernel. Summed one by one, each output's tangent was its own
evaluation, and so its own compile and run of the whole differentiated path tracer (4 orders x
N wavelengths of them).
"""

from __future__ import annotations

import drjit as dr

__all__ = ["PANELS_PER_KERNEL", "cut_kernel", "sum_blocks"]

#: Quadrature panels traced into one kernel before the next cut (:meth:`LineIntegral.integrate`).
PANELS_PER_KERNEL = 4


def cut_kernel(*state) -> None:
    """Evaluate ``state`` (Dr.Jit arrays, or lists, tuples and DRJIT_STRUCT objects of them) now,
    ending the kernel being traced, so that the work that follows compiles as a kernel of its
    own. Inside a symbolic loop, conditional or call nothing can be evaluated, and the kernel
    stays whole."""
    if dr.flag(dr.JitFlag.SymbolicScope):
        return
    dr.eval(*state)


def sum_blocks(values: list, block_size: int, slots: list, size: int):
    """A Float array of ``size`` zeros with, at ``slots[i][b]``, the sum of lanes
    ``b * block_size ... (b + 1) * block_size - 1`` of ``values[i]``. Every value is evaluated in
    one kernel first, then summed block by block in a fixed order (the same bits on every run).

    Differentiable in forward mode: the tangents of all ``values`` are evaluated together, in one
    kernel, and summed the same way."""
    return dr.custom(_BlockSums, values, block_size, slots, size)


class _BlockSums(dr.CustomOp):
    """:func:`sum_blocks` as a custom operation, whose forward derivative is the same sum of the
    values' tangents, evaluated together (a block sum evaluates its input, so the built-in
    derivative of each sum evaluated each tangent apart)."""

    def eval(self, values, block_size, slots, size):
        self.block_size, self.slots, self.size = block_size, slots, size
        return self._sum(values)

    def forward(self):
        self.set_grad_out(self._sum(self.grad_in("values")))

    def _sum(self, values):
        dr.eval(values)
        sums = dr.zeros(type(values[0]), self.size)
        for value, slot in zip(values, self.slots):
            dr.scatter(sums, dr.block_sum(value, self.block_size, mode="evaluated"), slot)
        # Run the scatters now: left pending, they would fuse into the next kernel traced (with
        # one lane per block, block_sum returns its input unevaluated), the next launch's path
        # tracer, making a second variant of it to compile (14 s on 2 cores, RGB): renders whose
        # single-scattering launch had 1 sample per target compiled it twice.
        dr.eval(sums)
        return sums

    def name(self):
        return "sum_blocks"
