"""Lab 0's contracts: each promise a student function's docstring makes, with the grader
test that fails when that promise alone is broken and, where one is shipped, the mutant
(``solutions/mutants/lab0.py``) that breaks just it. ``tests/meta/test_contracts.py``
keeps these lists, the graders and the mutants in step."""

BAD_INPUT = "test_pack_rgba8_unpack_rgba8_linear_to_srgb8_bad_input"
BAD_VIEWS = (
    "test_framebuffer_to_numpy_numpy_to_framebuffer_share_dlpack_cuda_array_interface_bad_input"
)
TRIANGLE = "test_render_rotating_triangle_coverage"

CONTRACTS = {
    "pack_rgba8": [
        (
            "word = R | G << 8 | B << 16 | A << 24: R in the low byte",
            "test_pack_rgba8_known_words",
            "pack_bgra_order",
        ),
        (
            "two's complement: alpha >= 128 gives a negative word (wrapped, never clamped)",
            "test_pack_rgba8_known_words",
            "pack_saturates_sign",
        ),
        ("any H, W >= 1", "test_pack_rgba8_unpack_rgba8_odd_and_large_sizes", None),
        (
            "any strided input gives its pixels' words, in a new contiguous tensor",
            "test_pack_rgba8_strided_views",
            None,
        ),
        (
            "TypeError / ValueError naming rgba for a non-tensor, a wrong shape or dtype",
            BAD_INPUT,
            None,
        ),
    ],
    "unpack_rgba8": [
        (
            "the inverse of pack for every bit pattern, negative words included (shift, not "
            "divide)",
            "test_pack_rgba8_unpack_rgba8_roundtrip",
            "unpack_truncating_division",
        ),
        (
            "each channel shifted down to bits 0-7, then masked",
            "test_pack_rgba8_unpack_rgba8_roundtrip",
            "unpack_masks_before_shifting",
        ),
        ("TypeError / ValueError naming packed", BAD_INPUT, None),
    ],
    "linear_to_srgb8": [
        (
            "code = floor(255 srgb + 0.5): rounded half up, not truncated",
            "test_linear_to_srgb8_every_level_boundary",
            "srgb_truncates",
        ),
        (
            "srgb is the OETF: linear toe up to 0.0031308, then the power curve",
            "test_linear_to_srgb8_every_level_boundary",
            "srgb_decode_threshold",
        ),
        (
            "any float dtype gives the float64 formula's code (half precision widened first)",
            "test_linear_to_srgb8_every_half_precision_value",
            "srgb_in_half_precision",
        ),
        ("clamped to [0, 1] before encoding", "test_linear_to_srgb8_extremes", "srgb_no_clamp"),
        ("NaN -> 0", "test_linear_to_srgb8_extremes", "srgb_nan_is_white"),
        ("+inf -> 255, -inf -> 0", "test_linear_to_srgb8_extremes", "srgb_posinf_is_black"),
        ("TypeError / ValueError naming img", BAD_INPUT, None),
    ],
    "framebuffer_to_numpy": [
        (
            "a view: same memory, writes seen both ways",
            "test_framebuffer_to_numpy_is_a_view",
            "numpy_copy",
        ),
        (
            "ValueError naming fb for a non-contiguous, non-int32 or non-2-D tensor",
            BAD_VIEWS,
            "numpy_accepts_strided",
        ),
        ("ValueError naming fb for a CUDA tensor", "test_framebuffer_to_numpy_is_a_view", None),
    ],
    "numpy_to_framebuffer": [
        ("a view: same memory", "test_numpy_to_framebuffer_is_a_view", "from_numpy_copy"),
        (
            "ValueError naming arr for a non-C-contiguous array (a transposed one too)",
            BAD_VIEWS,
            "numpy_accepts_fortran_order",
        ),
    ],
    "share_dlpack": [
        ("a new tensor over the same memory", "test_share_dlpack_same_memory", "dlpack_clone"),
        ("ValueError naming fb as _check_framebuffer", BAD_VIEWS, None),
    ],
    "cuda_array_interface": [
        (
            "shape, typestr <i4, (pointer, False), strides None, version 3, stream (1 for the "
            "default stream)",
            "test_cuda_array_interface",
            None,
        ),
        ("ValueError naming fb for a CPU tensor", "test_cuda_array_interface", None),
    ],
    "FrameDownloader": [
        (
            "shape sides of 1 are valid; the default num_buffers is 2",
            "test_FrameDownloader_bad_input",
            None,
        ),
        (
            "receive gives the oldest submitted frame (first in, first out)",
            "test_FrameDownloader_fifo_order_and_content",
            "downloader_lifo",
        ),
        (
            "each frame in flight has its own staging buffer (the ring advances)",
            "test_FrameDownloader_fifo_order_and_content",
            "downloader_ring_never_advances",
        ),
        (
            "RuntimeError when all num_buffers buffers are in flight",
            "test_FrameDownloader_refuses_overflow",
            "downloader_no_overflow_check",
        ),
        (
            "buffers allocated once, reused",
            "test_FrameDownloader_reuses_pinned_staging_buffers",
            "downloader_allocates_per_frame",
        ),
        (
            "receive returns the staging buffer itself, no copy",
            "test_FrameDownloader_reuses_pinned_staging_buffers",
            "receive_returns_a_copy",
        ),
        (
            "ValueError naming shape, num_buffers (an int >= 1) or frame",
            "test_FrameDownloader_bad_input",
            "downloader_accepts_zero_buffers",
        ),
    ],
    "measure_copy_bandwidth": [
        (
            "GB/s: nbytes / median / 1e9 (1e9 bytes, not 2**30)",
            "test_measure_copy_bandwidth_under_a_stub_clock",
            "bandwidth_in_gibibytes",
        ),
        (
            "the median of the timed copies, not the best",
            "test_measure_copy_bandwidth_under_a_stub_clock",
            "bandwidth_best_not_median",
        ),
        (
            "a positive finite float for every positive nbytes, 1 included",
            "test_measure_copy_bandwidth",
            None,
        ),
        (
            "ValueError naming nbytes or repeats unless a positive int",
            "test_measure_copy_bandwidth",
            None,
        ),
    ],
    "run_frame_loop": [
        (
            "every frame displayed once, in order, the last one too",
            "test_run_frame_loop_displays_every_frame_in_order",
            "loop_drops_last_frame",
        ),
        (
            "ValueError naming n_frames unless an int >= 1",
            "test_run_frame_loop_displays_every_frame_in_order",
            "frame_loop_accepts_zero_frames",
        ),
        (
            "two staging buffers, reused; frames, seconds, frames_per_second, displayed",
            "test_run_frame_loop_displays_every_frame_in_order",
            None,
        ),
    ],
    "render_rotating_triangle": [
        ("pixel (x, y) samples its centre (x + 0.5, y + 0.5)", TRIANGLE, "triangle_pixel_corners"),
        (
            "barycentrics divided by the signed area: either winding",
            TRIANGLE,
            "triangle_one_winding",
        ),
        ("outside: BACKGROUND_RGBA", TRIANGLE, "triangle_no_background"),
        ("inside: floor(255 b_k + 0.5), rounded half up", TRIANGLE, "triangle_truncates_colour"),
        (
            "out is (H, W): every pixel of a non-square frame",
            TRIANGLE,
            "triangle_width_height_swapped",
        ),
        (
            "the frame repeats every period frames",
            "test_render_rotating_triangle_period",
            "triangle_ignores_period",
        ),
        (
            "every pixel of out written in place; returns out",
            "test_render_rotating_triangle_writes_in_place",
            None,
        ),
        (
            "TypeError naming frame_index; ValueError naming period or out",
            "test_render_rotating_triangle_FrameLoop_bad_input",
            None,
        ),
    ],
    "FrameLoop": [
        (
            "one framebuffer, reused by every step",
            "test_FrameLoop_reuses_one_framebuffer",
            "frameloop_allocates_per_frame",
        ),
        (
            "step renders frame_index (from 0), then advances",
            "test_FrameLoop_reuses_one_framebuffer",
            "frameloop_advances_first",
        ),
        (
            "ValueError naming width or height unless a positive int",
            "test_render_rotating_triangle_FrameLoop_bad_input",
            None,
        ),
    ],
}
