"""Registers and spills of the ``plane_sampling: triton`` kernels, compiled without a GPU.

Compiles :mod:`eslam.field.triton_kernels` (forward, and the backward with both
gradients) for an NVIDIA target (default sm_90, an H100/H200) through Triton's own
compiler and assembles the PTX with the ``ptxas-blackwell`` that Triton ships (the PTX
is too new for its plain ``ptxas``), then prints ptxas's register and spill lines per
kernel, dtype and points-per-program block. This needs only the triton package: no
GPU, no CUDA driver. It says whether a block size spills, not how fast it runs.

Usage:
    python benchmarks/triton_ptxas.py [--arch 90] [--blocks 32 64 128] [--channels 32]
        [--warps 4]
"""

from __future__ import annotations

import argparse
import os
import re
import subprocess
import tempfile
from pathlib import Path

import triton
from triton.backends.compiler import GPUTarget
from triton.compiler import ASTSource

from eslam.field import triton_kernels

POINTERS = ("grad", "points", "window", "planes", "out", "grad_planes", "grad_points")
"""Pointer arguments of the kernels; ``points`` and ``window`` are float32 (the field's)."""

UNIT_STRIDES = ("stride_axis", "stride_channel", "stride_out_channel", "stride_grad_channel")
"""Strides that are 1 in the field's calls (contiguous points, channels-last planes,
contiguous outputs and gradients): Triton's launcher specialises an int argument equal
to 1 into a constant, which lets the compiler vectorise the channel loads."""


def signature(kernel, dtype: str) -> dict[str, str]:
    """Triton's signature of ``kernel``: planes-dtype pointers, i32 scalars, constexprs."""
    types = {}
    for name in kernel.arg_names:
        if name.isupper() or name in UNIT_STRIDES:
            types[name] = "constexpr"
        elif name in ("points", "window"):
            types[name] = "*fp32"
        elif name in POINTERS:
            types[name] = f"*{dtype}"
        else:
            types[name] = "i32"
    return types


def ptxas_report(ptx: str, arch: int) -> str:
    """ptxas's 'Used N registers' and spill lines for ``ptx``."""
    ptxas = Path(triton.__file__).parent / "backends" / "nvidia" / "bin" / "ptxas-blackwell"
    with tempfile.NamedTemporaryFile("w", suffix=".ptx") as file:
        file.write(ptx)
        file.flush()
        result = subprocess.run(
            [str(ptxas), "-v", f"--gpu-name=sm_{arch}a", file.name, "-o", os.devnull],
            capture_output=True,
            text=True,
            check=True,
        )
    registers = re.search(r"Used (\d+) registers", result.stderr)
    spills = re.search(r"(\d+) bytes spill stores, (\d+) bytes spill loads", result.stderr)
    return (
        f"{registers.group(1) if registers else '?'} registers, "
        f"{spills.group(1) if spills else '?'} B spill stores, "
        f"{spills.group(2) if spills else '?'} B spill loads"
    )


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--arch", type=int, default=90, help="compute capability, e.g. 90")
    parser.add_argument("--blocks", type=int, nargs="+", default=[32, 64, 128])
    parser.add_argument("--channels", type=int, default=32, help="features per plane row")
    parser.add_argument("--warps", type=int, default=4, help="warps per program (Triton: 4)")
    args = parser.parse_args(argv)
    if triton_kernels.INTERPRETED:
        parser.error("unset TRITON_INTERPRET: the interpreter's kernels cannot be compiled")
    target = GPUTarget("cuda", args.arch, 32)
    channels = triton.next_power_of_2(args.channels)
    print(
        f"| kernel | dtype | points per program "
        f"| sm_{args.arch}, C = {args.channels}, {args.warps} warps |"
    )
    print("|---|---|---:|---|")
    for name, kernel, flags in (
        ("forward", triton_kernels.sample_level_kernel, {}),
        (
            "backward",
            triton_kernels.sample_level_backward_kernel,
            {"NEED_PLANES": True, "NEED_POINTS": True},
        ),
    ):
        for dtype in ("fp32", "fp64"):
            for block in args.blocks:
                constants = dict(
                    flags, HAS_WINDOW=True, BLOCK_POINTS=block, BLOCK_CHANNELS=channels
                )
                constants.update({name: 1 for name in UNIT_STRIDES if name in kernel.arg_names})
                source = ASTSource(kernel, signature(kernel, dtype), constexprs=constants)
                compiled = triton.compile(source, target=target, options={"num_warps": args.warps})
                report = ptxas_report(compiled.asm["ptx"], args.arch)
                print(f"| {name} | {dtype} | {block} | {report} |")


if __name__ == "__main__":
    main()
