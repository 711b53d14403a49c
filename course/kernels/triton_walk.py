"""The BVH walk of the Triton tracers, as device functions (given, not an exercise).

How "one ray per thread" maps onto Triton. A Triton program works on a block of lanes in
lock step; control flow is per program, not per lane. So each kernel is a loop that runs
while *any* lane of the program still has work (``tl.max`` of the lanes' alive flags), and
every step is written with per-lane masks: a lane that is done, or has nothing of that
kind to do this step, just has its loads and stores masked off. This is what a CUDA warp
does with divergent branches anyway; the default launch (32 lanes, one warp per program)
makes a program exactly one warp, so the loop condition is a warp vote and the lanes of
different warps never wait for each other.

Each step of the walk does, per lane (see course.kernels.flat_bvh for the layouts and the
contract):

1. TRAVERSE: a lane at an interior node reads its row of ``pairs`` (both children's boxes
   and links: four 16-byte loads, the layout the CUDA C kernel reads), tests both boxes,
   goes to the nearer hit child and pushes the farther; a leaf child becomes pending work;
2. INTERSECT: a lane with pending leaf work tests one triangle (Möller–Trumbore, three
   16-byte loads), or two with ``tris_per_step=2``: not watertight (a ray through a shared
   edge or vertex may miss every triangle around it), while the box tests of TRAVERSE are
   conservative (``_slab``), so every miss is the triangle test's, as in flat_bvh;
3. POP: a lane with no node pops its stack (or finishes when it is empty and its leaf is
   done). With ``speculate`` it does so even while its leaf is being tested, parking at
   most one more leaf: it then takes part in both stages of a step instead of idling
   through one (Aila & Laine's speculative traversal).

Stages no lane needs are skipped (``uniform_branches``): before TRAVERSE and INTERSECT the
program votes over its lanes (``redux.sync``) and branches around the stage when none needs
it, as a warp does when none of its threads takes a branch. ``_while_while`` is the CUDA C
kernel's loop shape instead (Aila & Laine's while-while: traverse while some lane looks for
a leaf, then test while some lane has one).

Loads as CUDA C does them: one 64-bit address per row (``_row``) whose words ``_load4``
reads at constant offsets, and the triangle's inside test as one NaN-propagating min rather
than flags packed into bits. ``bench/sass_loops.py`` counts the instructions per TRAVERSE
and INTERSECT iteration of both kernels; bench/results/nvidia-h200/lab3_rows/ holds them.

The stack. Triton has no per-lane arrays with dynamic indices, so with ``stack="global"``
each lane's stack is a column of a scratch buffer in global memory, ``stack[level,
lane]``: entries of one level of neighbouring lanes are neighbours, so pushes and pops of a
warp at similar depths touch few cache lines (the interleaving CUDA gives local memory). It
is what the CUDA kernel's local-memory stack is, too: both live in L1/L2-cached device
memory. A lane owns its column for the program's lifetime, so nothing needs synchronising.
With ``stack_regs=4`` the top four entries stay in registers (shifted on every push and
pop) and only deeper ones go to the buffer. ``stack="local"`` declares a 64-entry array in
each lane's local memory in inline PTX instead (``_local_stack``), as ``int stack[64]`` is
in CUDA C: no buffer is allocated, and the hardware interleaves the lanes' entries itself.

The launch knobs' defaults are here too (``DEFAULT_*``); their launchers are in
:mod:`course.kernels.triton_tracer` and :mod:`course.kernels.triton_whitted`.

Its parts, each importing only those before it: :mod:`~course.kernels.triton_walk_loads`
(the walk's constants, ray and row loads, the box test),
:mod:`~course.kernels.triton_walk_stack` (the stack),
:mod:`~course.kernels.triton_walk_steps` (visit, intersect, pop, start) and
:mod:`~course.kernels.triton_walk_loops` (the if-if round, the while-while loop, ``_trace``);
this module re-exports what the launchers import.
"""

from __future__ import annotations

from course.kernels.triton_walk_loads import LOCAL_STACK as LOCAL_STACK
from course.kernels.triton_walk_loads import NONE as NONE
from course.kernels.triton_walk_loads import _load_rays as _load_rays
from course.kernels.triton_walk_loads import _or as _or
from course.kernels.triton_walk_loads import _store_row_hits as _store_row_hits
from course.kernels.triton_walk_loops import _trace as _trace
from course.kernels.triton_walk_loops import _while_round as _while_round
from course.kernels.triton_walk_stack import _local_stack as _local_stack
from course.kernels.triton_walk_steps import _start as _start

DEFAULT_BLOCK = 32
DEFAULT_NUM_WARPS = 1
DEFAULT_UNIFORM = True
# The defaults are the launch timed fastest on primary and diffuse rays together
# (bench/results/nvidia-h200/lab3_head_to_head/): while-while, speculative, local stack.
# Refilling free lanes is off: it gains on diffuse rays what it loses on primary ones
# (bench/results/nvidia-h200/lab3_refill/ and lab3_rows/); pass refill=8 for incoherent rays.
DEFAULT_STACK_REGS = 0
DEFAULT_TRIS_PER_STEP = 1
DEFAULT_SPECULATE = True
DEFAULT_LOOP = "while"
DEFAULT_STACK = None  # "local", or "global" when stack_regs keeps entries in registers
DEFAULT_REFILL = 0  # free lanes at which a persistent program takes new rays (0: off)
LOOPS = ("if", "while")
STACKS = ("global", "local")
# The uber kernel's walk, as timed for its frames (bench/results/nvidia-h200/lab3_packed/).
UBER_STACK_REGS, UBER_TRIS_PER_STEP, UBER_SPECULATE = 4, 1, False
