"""The loops of the Triton BVH walk in machine code, without a GPU: instructions per loop.

    python bench/sass_loops.py [--arch 90] [--sass FILE ...] [--out DIR]

Compiles ``course.kernels.triton_tracer``'s walk (``_trace_kernel`` with the defaults of
``trace_flat_triton``, and the refill kernel) for an NVIDIA architecture with the ptxas
that ships with Triton, disassembles it (``cuobjdump -sass``, shipped too) and prints each
loop (a backward branch) with its instruction count: the TRAVERSE loop, the INTERSECT loop
and the round around them. ``--sass`` reads a disassembly made elsewhere instead (e.g.
``cuobjdump -sass`` of the CUDA C tracer's extension on a GPU machine), one report per
function in it. Counts are static: a loop's instructions, each branch arm included; what
a warp executes per iteration is at most that. Writes ``sass_loops.txt`` (and the
disassemblies) to ``--out`` when given; ``--json`` prints the loops of each listing as
JSON instead of the text (tests/test_sass_loops.py reads it).
"""

from __future__ import annotations

import argparse
import json
import os
import re
import subprocess
import sys
import tempfile
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

_INSTRUCTION = re.compile(r"/\*([0-9a-f]{4,})\*/\s+(.*?);")
_BRANCH = re.compile(r"BRA\s+(?:\S+,\s*)?(0x[0-9a-f]+)")


def loops(sass: str) -> list[dict]:
    """The loops of each function of a ``cuobjdump -sass`` listing: ``{"function",
    "start", "end", "instructions"}`` per backward branch, innermost first."""
    found = []
    for name, body in _functions(sass):
        rows = [(int(m.group(1), 16), m.group(2)) for m in _INSTRUCTION.finditer(body)]
        for at, text in rows:
            branch = _BRANCH.search(text)
            if branch and int(branch.group(1), 16) < at:
                start = int(branch.group(1), 16)
                count = sum(1 for a, _ in rows if start <= a <= at)
                found.append({"function": name, "start": start, "end": at, "instructions": count})
    return sorted(found, key=lambda f: (f["function"], f["end"] - f["start"]))


def _functions(sass: str):
    parts = re.split(r"\n\s*Function : (\S+)", "\n" + sass)
    return list(zip(parts[1::2], parts[2::2])) or [("?", sass)]


def _tool(name: str) -> str:
    import triton

    path = Path(triton.__file__).parent / "backends" / "nvidia" / "bin" / name
    return str(path) if path.exists() else name


def compile_walk(arch: int, refill: bool) -> str:
    """SASS of the default walk (``refill``: the refill kernel) for ``sm_<arch>``."""
    import triton
    from triton.backends.compiler import GPUTarget
    from triton.compiler import ASTSource

    from course.kernels import triton_tracer as tt
    from course.kernels.flat_bvh import EXIT_SCALE

    kernel = tt._refill_kernel if refill else tt._trace_kernel
    # The kernel's own arguments, typed by name (every other one is a float32 pointer).
    types = {
        "tlo_value": "fp32",
        "thi_value": "fp32",
        "root_ref": "i32",
        "n_rays": "i32",
        "stride": "i32",
        "pairs": "*i32",
        "tris": "*i32",
        "stack_ptr": "*i32",
        "counter": "*i32",
        "id_ptr": "*i64",
    }
    signature = {p.name: types.get(p.name, "*fp32") for p in kernel.params if not p.is_constexpr}
    constants = {
        "BLOCK": tt.DEFAULT_BLOCK,
        "ANY_HIT": False,
        "EXIT": EXIT_SCALE,
        "VEC": True,
        "SANITIZE": False,
        "REGS": tt.LOCAL_STACK,
        "TRIS": tt.DEFAULT_TRIS_PER_STEP,
        "SPECULATE": tt.DEFAULT_SPECULATE,
        "TLO_ARRAY": False,
        "THI_ARRAY": False,
    }
    if refill:
        constants["REFILL"] = 8
    else:
        constants.update(UNIFORM=tt.DEFAULT_UNIFORM, WHILE=tt.DEFAULT_LOOP == "while")
    signature.update({c: "constexpr" for c in constants})
    compiled = triton.compile(
        ASTSource(fn=kernel, signature=signature, constexprs=constants),
        target=GPUTarget("cuda", arch, 32),
        options={"num_warps": tt.DEFAULT_NUM_WARPS},
    )
    with tempfile.TemporaryDirectory() as tmp:
        cubin = Path(tmp) / "walk.cubin"
        cubin.write_bytes(compiled.asm["cubin"])
        return subprocess.run(
            [_tool("cuobjdump"), "-sass", str(cubin)], check=True, capture_output=True, text=True
        ).stdout


def report(title: str, sass: str) -> str:
    lines = [title]
    for loop in loops(sass):
        lines.append(
            f"  {loop['function'][:60]}: loop {loop['start']:#06x}..{loop['end']:#06x}"
            f" {loop['instructions']} instructions"
        )
    return "\n".join(lines)


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--arch", type=int, default=90, help="compute capability x 10")
    parser.add_argument(
        "--sass",
        type=Path,
        nargs="*",
        default=[],
        help="disassemblies to read instead of compiling",
    )
    parser.add_argument("--out", type=Path)
    parser.add_argument("--json", action="store_true", help="print the loops as JSON")
    args = parser.parse_args(argv)
    texts, dumps = [], {}
    if args.sass:
        for path in args.sass:
            texts.append(report(str(path), path.read_text()))
    else:
        os.environ.pop("TRITON_INTERPRET", None)
        import triton

        for refill in (False, True):
            sass = compile_walk(args.arch, refill)
            name = "refill" if refill else "walk"
            dumps[f"triton_{name}.sass"] = sass
            texts.append(
                report(
                    f"Triton {triton.__version__}, sm_{args.arch}, "
                    f"{'refill kernel (refill=8)' if refill else 'the defaults'}:",
                    sass,
                )
            )
    text = "\n".join(texts)
    if args.json:
        found = {name: loops(sass) for name, sass in dumps.items()}
        found.update({str(path): loops(path.read_text()) for path in args.sass})
        print(json.dumps(found))
    else:
        print(text)
    if args.out:
        args.out.mkdir(parents=True, exist_ok=True)
        (args.out / "sass_loops.txt").write_text(
            f"{' '.join(['bench/sass_loops.py', *(argv or sys.argv[1:])])}\n\n{text}\n"
        )
        for name, sass in dumps.items():
            (args.out / name).write_text(sass)


if __name__ == "__main__":
    main()
