"""Lab 6's ``rasterize`` as fused Triton kernels: the compute rasterizer of the lecture.

Lab 6 writes the rasterizer as batched torch code: every triangle's bounding box is
enumerated into a tensor of fragments (triangle, pixel), each fragment's edge functions,
depth and key are computed by a dozen tensor operations, and one ``scatter_reduce`` does
the atomic minimum. That is the right way to *learn* it, but every intermediate makes a
trip through DRAM. A compute-shader rasterizer keeps a fragment in registers from the
inside test to the ``atomicMin``. These kernels are that design, given (not an exercise),
so the lab can measure raster against ray-traced visibility with both sides fused
(``course.kernels.triton_tracer`` is the other side).

Two raster kernels, because triangle sizes on screen differ by orders of magnitude:

* ``_small_kernel`` runs over every triangle, one lane each. A small one (bounding box up to
  ``SMALL_BOX`` pixels, nearly all of a dense mesh) loops over its own box; the block loops
  as long as its largest small box, so they are kept small. A larger one is appended to a
  queue on the device (an atomic counter); empty, non-finite, zero-area, off-screen and
  culled triangles get an empty box and cost nothing more.
* ``_large_kernel`` runs a fixed grid (a few programs per SM) over the queue: each queued
  triangle gets one program whose lanes spread over its box, and a huge one (over
  ``HUGE_BOX`` pixels, e.g. a floor filling the screen) is split over all programs.
  The queue replaces one program per triangle (nearly all of them leaving at once);
  ``bench/lab6_raster.py`` times both kernels (bunny_x4, 278K triangles, at 1080p), the
  figures in bench/results/<gpu>/lab6*/.

Nothing goes back to the host: no sort, compaction or count is read, so a frame has no
synchronisation.

``screen_triangles_triton`` is the lab's setup (``to_clip_space``, ``clip_triangles``,
``to_screen``) as one kernel, one lane per face, writing slot ``i`` (face i or its first
piece) and slot ``F + i`` (the second piece of a face the near plane cuts into a quad) of a
(2F, 3, 4) buffer, NaN where there is no triangle. ``visibility_fused`` chains it with the
raster kernels and an id map: camera matrix to (H, W) face ids in four kernels (the vertex
kernel also clears the visibility buffer). ``FusedVisibility`` records those four in a CUDA
graph: at 1080p the Python launches take longer than the kernels. The kernels themselves are
in :mod:`course.kernels.triton_raster_kernels`.

The arithmetic is Lab 6's contract (``solutions``' docstrings state it in full): clip
coordinates in float64 rounded once, trivial rejection, near-plane crossings interpolated
from the inside corner; screen positions ``(x, y, z_ndc, 1/w)``; bounding boxes of pixel
centres clamped to the screen; consistent edge functions (evaluated from the
lexicographically smaller endpoint, so a shared edge gives exactly opposite values); the
top-left fill rule; depth interpolated from corner 0; 32-bit keys from the float bits of
the view depth ``1 / lerp(1/w)`` or 24-bit unorm window depth; fragments beyond the far
plane dropped; ``key = depth << 32 | id``, resolved by ``atomic_min``. The kernels are
compiled without FMA contraction (``enable_fp_fusion=False``; ``FP_FUSION`` for the raster
kernels, whose speed on an H100 did not change) and divide with correctly rounded
``div_rn``, so every value is the torch version's, bit for bit, and so are the keys. What
remains is the order of the triangles: keys hold slot numbers, so an exact depth tie (two
coplanar overlapping triangles) between the second piece of a clipped face and another
face resolves by slot, not by face number as in the lab (``tests/meta/test_triton_raster.py``
bounds how often; none occurred in its scenes or in the benchmark's).
"""

from __future__ import annotations

import torch

from course.kernels.triton_intersect import _ieee_quiet, _require_triton, interpreting, triton
from course.kernels.triton_raster_kernels import (
    _ids_kernel,
    _large_kernel,
    _small_kernel,
    _vertex_kernel,
)

__all__ = [
    "EMPTY",
    "SMALL_BOX",
    "FusedVisibility",
    "rasterize_triton",
    "screen_triangles_fast",
    "screen_triangles_triton",
    "visibility_fused",
]

EMPTY = torch.iinfo(torch.int64).max  # the key of a pixel no fragment reached
# Launch settings (module attributes, read at every launch; bench/lab6_raster.py's sweep).
SMALL_BOX = 64  # pixels: boxes up to this size go to the lane-per-triangle kernel
HUGE_BOX = 16384  # pixels: boxes above this size are split over all large-kernel programs
BLOCK_TRIANGLES = 64  # lanes (triangles) per program of the small kernel
SMALL_WARPS = 2
BLOCK_PIXELS = 256  # lanes (pixels) per program of the large kernel
LARGE_WARPS = 4
LARGE_PROGRAMS_PER_SM = 4
BLOCK_FACES = 128  # faces per program of the vertex kernel
FILL_KEYS = 4096  # keys cleared per program of the vertex kernel
BLOCK_IDS = 1024
FP_FUSION = False  # no FMA contraction in the raster kernels: the lab's keys bit for bit


# ---------------------------------------------------------------------------------------
# Launchers


def _programs(device: torch.device) -> int:
    """The fixed grid of ``_large_kernel``: a few programs per SM (2 when interpreting)."""
    if interpreting():
        return 2
    index = device.index if device.index is not None else torch.cuda.current_device()
    if index not in _SM_COUNT:
        _SM_COUNT[index] = torch.cuda.get_device_properties(index).multi_processor_count
    return LARGE_PROGRAMS_PER_SM * _SM_COUNT[index]


_SM_COUNT: dict[int, int] = {}


def _raster_launch(
    screen,
    out,
    queue,
    counter,
    count: int,
    width: int,
    height: int,
    depth_bits: int,
    cull: bool,
    small_box: int,
    huge_box: int,
) -> None:
    """The two raster kernels on ``screen`` (count, 3, 4) float32; ``out`` cleared to
    EMPTY, ``counter`` (2,) int32 zeroed, ``queue`` (2 * count,) int32 scratch."""
    _small_kernel[(triton.cdiv(count, BLOCK_TRIANGLES),)](
        screen,
        out,
        queue,
        counter,
        count,
        width,
        height,
        small_box,
        huge_box,
        DEPTH_BITS=depth_bits,
        CULL=cull,
        BLOCK=BLOCK_TRIANGLES,
        num_warps=SMALL_WARPS,
        enable_fp_fusion=FP_FUSION,
    )
    _large_kernel[(_programs(screen.device),)](
        screen,
        out,
        queue,
        counter,
        count,
        width,
        height,
        DEPTH_BITS=depth_bits,
        CULL=cull,
        BLOCK=BLOCK_PIXELS,
        num_warps=LARGE_WARPS,
        enable_fp_fusion=FP_FUSION,
    )


def _check_viewport(width, height) -> None:
    for name, value in (("width", width), ("height", height)):
        if isinstance(value, bool) or not isinstance(value, int) or not 0 < value < 2**15:
            raise ValueError(f"{name}: expected an int in [1, 32767], got {value!r}")


def _check_knobs(depth_bits, small_box, huge_box=HUGE_BOX) -> None:
    if depth_bits not in (24, 32):
        raise ValueError(f"depth_bits: expected 24 or 32, got {depth_bits!r}")
    # The small kernel compares every lane's box size (0 for lanes past the last triangle)
    # with these: below 0, every lane of a block is queued, past the end of the queue (the
    # interpreter corrupted its heap on small_box=-1); None or a string fails inside Triton.
    for name, value in (("small_box", small_box), ("huge_box", huge_box)):
        if isinstance(value, bool) or not isinstance(value, int) or value < 0:
            raise ValueError(f"{name}: expected an int >= 0 (pixels), got {value!r}")


def _check_device(device: torch.device, name: str) -> None:
    if not interpreting() and device.type != "cuda":
        raise ValueError(
            f"{name}: the compiled Triton kernels need a CUDA tensor, got {device} "
            "(for the CPU, set TRITON_INTERPRET=1 before importing triton)"
        )


def rasterize_triton(
    screen: torch.Tensor,
    width: int,
    height: int,
    *,
    depth_bits: int = 32,
    cull_backfaces: bool = False,
    out: torch.Tensor | None = None,
    small_box: int = SMALL_BOX,
    huge_box: int | None = None,
) -> torch.Tensor:
    """Lab 6's ``rasterize`` (same arguments and keys), fused: (width * height,) int64.

    screen: (K, 3, 4) float ``(x, y, z_ndc, 1/w)`` (computed in float32); width, height:
    the viewport; depth_bits: 32 or 24; cull_backfaces: drop negative-area triangles;
    out: optional (width * height,) int64 buffer (every element written); small_box: the
    box size, in pixels, up to which a triangle gets one lane rather than a program;
    huge_box: above it, a triangle is split over all programs (default ``HUGE_BOX``).
    """
    _require_triton()
    if (
        not isinstance(screen, torch.Tensor)
        or screen.ndim != 3
        or screen.shape[1:] != (3, 4)
        or not screen.is_floating_point()
    ):
        got = tuple(screen.shape) if isinstance(screen, torch.Tensor) else type(screen).__name__
        raise ValueError(f"screen: expected a (K, 3, 4) float tensor (x, y, z_ndc, 1/w), got {got}")
    _check_viewport(width, height)
    _check_knobs(depth_bits, small_box, HUGE_BOX if huge_box is None else huge_box)
    device = screen.device
    _check_device(device, "screen")
    if out is None:
        out = torch.empty(width * height, dtype=torch.int64, device=device)
    if out.shape != (width * height,) or out.dtype != torch.int64 or out.device != device:
        raise ValueError(
            f"out: expected a ({width * height},) int64 tensor on {device}, got "
            f"{tuple(out.shape)} {out.dtype} on {out.device}"
        )
    out.fill_(EMPTY)
    data = screen.to(torch.float32).contiguous()
    count = data.shape[0]
    if count:  # no host synchronisation: the queues of large triangles stay on the device
        counter = torch.zeros(2, dtype=torch.int32, device=device)
        queue = torch.empty(2 * count, dtype=torch.int32, device=device)
        with _ieee_quiet():
            _raster_launch(
                data,
                out,
                queue,
                counter,
                count,
                width,
                height,
                depth_bits,
                cull_backfaces,
                small_box,
                HUGE_BOX if huge_box is None else huge_box,
            )
    return out


def _mesh_arguments(vertices, faces, mvp, width, height, depth_bits=32, small_box=SMALL_BOX):
    """Checked arguments of the mesh entry points. The device comes last: on a machine
    without CUDA every other bad argument is still named, not reported as a CPU tensor."""
    _require_triton()
    if (
        not isinstance(vertices, torch.Tensor)
        or vertices.ndim != 2
        or vertices.shape[1] != 3
        or vertices.dtype not in (torch.float32, torch.float64)
    ):
        got = (
            f"{tuple(vertices.shape)} {vertices.dtype}"
            if isinstance(vertices, torch.Tensor)
            else type(vertices).__name__
        )
        raise ValueError(f"vertices: expected a (V, 3) float32/float64 tensor, got {got}")
    if (
        not isinstance(faces, torch.Tensor)
        or faces.ndim != 2
        or faces.shape[1] != 3
        or faces.dtype not in (torch.int32, torch.int64)
    ):
        got = (
            f"{tuple(faces.shape)} {faces.dtype}"
            if isinstance(faces, torch.Tensor)
            else type(faces).__name__
        )
        raise ValueError(f"faces: expected an (F, 3) int32/int64 tensor, got {got}")
    if not isinstance(mvp, torch.Tensor) or mvp.shape != (4, 4) or not mvp.is_floating_point():
        got = tuple(mvp.shape) if isinstance(mvp, torch.Tensor) else type(mvp).__name__
        raise ValueError(f"mvp: expected a (4, 4) float tensor, got {got}")
    device = vertices.device
    if faces.device != device:
        raise ValueError(f"faces: expected a tensor on {device} like vertices, got {faces.device}")
    _check_viewport(width, height)
    _check_knobs(depth_bits, small_box)
    _check_device(device, "vertices")
    # A CPU matrix is copied without a synchronisation (the copy is queued like a kernel).
    m = mvp.to(device=device, dtype=torch.float64, non_blocking=True).contiguous()
    return vertices.contiguous(), faces.contiguous(), m


def _vertex_launch(vertices, faces, mvp, screen, keys, counter, width, height) -> None:
    count = faces.shape[0]
    n_keys = 0 if keys is None else keys.shape[0]
    grid = max(triton.cdiv(count, BLOCK_FACES), triton.cdiv(n_keys, FILL_KEYS))
    _vertex_kernel[(grid,)](
        vertices,
        faces,
        mvp,
        screen,
        screen if keys is None else keys,
        screen if counter is None else counter,
        count,
        n_keys,
        width / 2,
        height / 2,
        BLOCK=BLOCK_FACES,
        FILL=FILL_KEYS,
        PREPARE=keys is not None,
        num_warps=4,
        enable_fp_fusion=False,
    )


def screen_triangles_triton(
    vertices: torch.Tensor, faces: torch.Tensor, mvp: torch.Tensor, width: int, height: int
) -> torch.Tensor:
    """Lab 6's ``to_clip_space``, ``clip_triangles`` and ``to_screen`` in one kernel.

    vertices: (V, 3) float32 (float64 is rounded to float32 clip coordinates); faces: (F, 3)
    int64/int32 indices into vertices (not range-checked: that would cost a
    synchronisation); mvp: (4, 4) float, used in float64 (``to_clip_space``'s contract);
    width, height: the viewport. Returns (2F, 3, 4) float32 ``(x, y, z_ndc, 1/w)``: slot
    ``i`` is face i (its first piece when the near plane cuts it), slot ``F + i`` the second
    piece of a face cut into a quad, and every coordinate of a slot holding nothing (a
    rejected face, no second piece) is NaN, which every rasterizer draws as nothing. The
    pieces are those of the lab, bit for bit (same operations, no FMA contraction, correctly
    rounded divisions); their order differs: source face = slot mod F.
    """
    vertices, faces, m = _mesh_arguments(vertices, faces, mvp, width, height)
    screen = torch.empty(2 * faces.shape[0], 3, 4, dtype=torch.float32, device=vertices.device)
    if faces.shape[0]:
        with _ieee_quiet():
            _vertex_launch(vertices, faces, m, screen, None, None, width, height)
    return screen


def visibility_fused(
    vertices: torch.Tensor,
    faces: torch.Tensor,
    mvp: torch.Tensor,
    width: int,
    height: int,
    *,
    depth_bits: int = 32,
    cull_backfaces: bool = False,
    small_box: int = SMALL_BOX,
) -> torch.Tensor:
    """Primary visibility of a mesh: (height, width) int64 source-face ids, -1 where empty.

    Lab 6's pipeline (``to_clip_space`` .. ``rasterize``, ids through ``source``) in four
    kernels and no host synchronisation: ``_vertex_kernel`` (MVP, clipping, viewport; it
    also clears the visibility buffer), ``_small_kernel``, ``_large_kernel`` and the id map,
    written in place over the keys. Arguments as ``screen_triangles_triton``; depth_bits,
    cull_backfaces, small_box as ``rasterize_triton``. The keys are the lab's for the
    triangles of ``screen_triangles_triton``: the same pixels see the same faces, except
    that an exact depth tie between a face's second piece and another face goes to the
    other face here (slot order), to the lower face in the lab.
    """
    vertices, faces, m = _mesh_arguments(vertices, faces, mvp, width, height, depth_bits, small_box)
    device, count = vertices.device, faces.shape[0]
    if count == 0:
        return torch.full((height, width), -1, dtype=torch.int64, device=device)
    keys = torch.empty(width * height, dtype=torch.int64, device=device)
    screen = torch.empty(2 * count, 3, 4, dtype=torch.float32, device=device)
    counter = torch.empty(2, dtype=torch.int32, device=device)  # zeroed by the vertex kernel
    queue = torch.empty(4 * count, dtype=torch.int32, device=device)
    with _ieee_quiet():
        _vertex_launch(vertices, faces, m, screen, keys, counter, width, height)
        _raster_launch(
            screen,
            keys,
            queue,
            counter,
            2 * count,
            width,
            height,
            depth_bits,
            cull_backfaces,
            small_box,
            HUGE_BOX,
        )
        _ids_kernel[(triton.cdiv(keys.shape[0], BLOCK_IDS),)](
            keys, keys.shape[0], count, BLOCK=BLOCK_IDS, num_warps=4
        )
    return keys.view(height, width)


class FusedVisibility:
    """``visibility_fused`` for one mesh and viewport, recorded once as a CUDA graph.

    ``FusedVisibility(vertices, faces, width, height, ...)(mvp)`` returns what
    ``visibility_fused(vertices, faces, mvp, width, height, ...)`` returns (a new tensor
    each call). The first call on CUDA runs the pipeline once (compiling the kernels) and
    records its four kernels in a graph; every later call copies the 4x4 matrix into the
    graph's input, replays the graph and copies the ids out: one launch instead of four
    kernel launches with their Python argument handling, which at 1080p take longer on the
    host than the kernels on the GPU. The graph reads ``vertices`` and ``faces`` where they
    are: their contents may change between calls, not their storage (shape, dtype, place);
    this object keeps them alive. Without CUDA (Triton's interpreter) every call runs
    ``visibility_fused``.
    """

    def __init__(
        self,
        vertices: torch.Tensor,
        faces: torch.Tensor,
        width: int,
        height: int,
        *,
        depth_bits: int = 32,
        cull_backfaces: bool = False,
        small_box: int = SMALL_BOX,
    ) -> None:
        # A stand-in matrix on the CPU: vertices, not yet checked, may have no device.
        eye = torch.eye(4, dtype=torch.float64)
        vertices, faces, _ = _mesh_arguments(
            vertices, faces, eye, width, height, depth_bits, small_box
        )
        self.vertices, self.faces, self.width, self.height = vertices, faces, width, height
        self.knobs = {
            "depth_bits": depth_bits,
            "cull_backfaces": cull_backfaces,
            "small_box": small_box,
        }
        self._graph = None
        self._mvp = None
        self._ids = None

    def _eager(self, mvp: torch.Tensor) -> torch.Tensor:
        return visibility_fused(
            self.vertices, self.faces, mvp, self.width, self.height, **self.knobs
        )

    def __call__(self, mvp: torch.Tensor) -> torch.Tensor:
        device = self.vertices.device
        if device.type != "cuda" or interpreting():
            return self._eager(mvp)
        if not isinstance(mvp, torch.Tensor) or mvp.shape != (4, 4) or not mvp.is_floating_point():
            got = tuple(mvp.shape) if isinstance(mvp, torch.Tensor) else type(mvp).__name__
            raise ValueError(f"mvp: expected a (4, 4) float tensor, got {got}")
        if self._graph is None:
            self._mvp = torch.empty(4, 4, dtype=torch.float64, device=device)
            self._mvp.copy_(mvp)
            side = torch.cuda.Stream(device)
            side.wait_stream(torch.cuda.current_stream(device))
            with torch.cuda.stream(side):
                self._eager(self._mvp)  # compiles and loads the kernels outside the capture
            torch.cuda.current_stream(device).wait_stream(side)
            graph = torch.cuda.CUDAGraph()
            with torch.cuda.graph(graph):
                self._ids = self._eager(self._mvp)
            self._graph = graph
        # A small copy from pageable memory is queued without waiting for the GPU.
        self._mvp.copy_(mvp, non_blocking=True)
        self._graph.replay()
        return self._ids.clone()


def screen_triangles_fast(
    clip_vertices: torch.Tensor,
    faces: torch.Tensor,
    width: int,
    height: int,
    clip_triangles,
    to_screen,
):
    """Lab 6's setup stages (``clip_triangles`` then ``to_screen``), cheap for most triangles.

    clip_vertices: (V, 4) clip coordinates (``to_clip_space``); faces: (F, 3) int64;
    clip_triangles, to_screen: the lab's functions, used for the triangles that need them.
    Returns ``(screen (K, 3, 4), source (K,) int64)`` like ``to_screen(clip_triangles(...))``
    but in another order: first the triangles entirely on the visible side of the near
    plane (no clipping: only the viewport, a handful of element-wise kernels), then what
    ``clip_triangles`` makes of the others (near-plane crossings, NaN/inf corners). Trivially
    rejected triangles are not removed from the first group: their clamped boxes are empty,
    or they cover nothing, which costs less than a compaction. Ids index the returned
    ``screen``; exact depth ties may therefore go to another triangle than in the lab's
    order (visible only as coplanar z-fighting).
    """
    clip = clip_vertices[faces]  # (F, 3, 4)
    d = clip[..., 2] + clip[..., 3]
    simple = (d >= 0).all(-1) & (clip[..., 3] > 0).all(-1) & torch.isfinite(clip).all(-1).all(-1)
    first = simple.nonzero()[:, 0]
    rest = (~simple).nonzero()[:, 0]
    parts, sources = [], []
    if len(first):
        parts.append(to_screen(clip[first], width, height))
        sources.append(first)
    if len(rest):
        clipped, source, _ = clip_triangles(clip[rest])
        if len(source):
            parts.append(to_screen(clipped, width, height))
            sources.append(rest[source])
    if not parts:
        return clip.new_zeros(0, 3, 4), faces.new_zeros(0)
    return torch.cat(parts), torch.cat(sources)
