"""Task 3: ``render_uber``, the bounce loop as one fused program over fixed-size lane buffers
(two step functions ``torch.compile`` captures whole).
"""

from __future__ import annotations

import functools
import math

import torch

from course.given.lab3 import (
    MAX_DEPTH,
    WhittedScene,
    check_render_inputs,
    dot,
    normalize,
    offset_scale,
)


def render_uber(
    scene: WhittedScene,
    origins: torch.Tensor,
    directions: torch.Tensor,
    trace,
    max_depth: int = MAX_DEPTH,
    compile=False,
) -> torch.Tensor:
    """The bounce loop as one fused program over fixed-size lane buffers.

    Same arguments and image as :func:`render_whitted`; compile: False (eager), True
    (``torch.compile`` with inductor) or a ``torch.compile`` backend, by name (e.g.
    ``"eager"``: capture only) or a callable (``backend=`` of ``torch.compile``). Returns
    (N, 3).

    A GPU uber kernel is one thread per pixel running TRAVERSE -> INTERSECT -> SHADE ->
    (reflect) as a state machine: no ray state goes back to memory between stages, but a
    thread whose ray is done idles until its whole warp is. Write the torch analogue: N
    lanes (and N x L shadow lanes) whose buffers **never change size**. Each bounce:

    1. ``trace`` all N lanes (dead lanes: an empty interval);
    2. a step function builds the hits' surfaces and all N x L shadow rays (an empty
       interval where a lane is dead or ``n . l <= 0``);
    3. ``trace`` all N x L shadow lanes with ``any_hit=True``;
    4. a step function shades, accumulates the image and spawns (``torch.where``).

    The two step functions must contain no data-dependent shapes (no ``x[mask]``,
    ``nonzero``, ``.item()``, ``if`` on tensor values), so ``torch.compile(step,
    backend=..., fullgraph=True)`` captures each as one graph of fixed-size tensors and
    fuses it (the grader inspects the captured graphs); the tracer stays outside (on a GPU
    the Triton uber kernel fuses the traversal too: ``course.kernels.triton_tracer``).

    Errors (the provided check): ValueError or TypeError naming ``scene`` (not a
    ``WhittedScene``, a scene without ``lights``, a ``material`` index beyond its table),
    ``origins`` or ``directions`` (a wrong shape; TypeError for half precision or a dtype
    other than the scene's), ``trace`` (not callable) or ``max_depth`` (not an int >= 0).
    TypeError naming ``compile`` for a value of another type.

    Hints: pass the scene's tensors to the step functions one by one (not the dataclass);
    cache the compiled functions (``functools.cache``) so a second call does not recompile.
    """
    # Provided: validates the arguments (ValueError/TypeError naming the argument).
    n = check_render_inputs(  # noqa: F841 (n: the number of rays, for your code)
        scene, origins, directions, trace, max_depth
    )
    if not (isinstance(compile, (bool, str)) or callable(compile)):
        raise TypeError(
            f"compile: expected a bool or a torch.compile backend (a name or a "
            f"callable), got {compile!r}"
        )
    raise NotImplementedError("not implemented yet: render_uber (task 3)")
