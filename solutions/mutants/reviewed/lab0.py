"""Lab 0's generated mutants that survive the graders, reviewed (see
``solutions/mutants/reviewed/__init__.py``)."""

EQUIVALENT = {
    "lab0_interop:linear_to_srgb8:const_float:1": (
        "posinf=1.1 is clamped to 1 by the next clamp(0, 1) (and srgb_encode clamps again): +inf "
        "still gives 255"
    ),
    "lab0_interop:linear_to_srgb8:const_float:4": (
        "srgb_encode clamps its input to [0, 1] itself, so clamp(0, 1.1) encodes the same values"
    ),
    "lab0_interop:measure_copy_bandwidth:const_int:3": (
        "warmup=2 instead of 1 only changes how long the measurement runs"
    ),
    "lab0_interop:pack_rgba8:const_int:10": (
        "3**31 never matches, but the int64 -> int32 cast wraps modulo 2**32 on CPU and CUDA, "
        "giving the same two's-complement word"
    ),
    "lab0_interop:pack_rgba8:op_Sub_Add:0": (
        "word + 2**32 equals word - 2**32 modulo 2**32, and the int64 -> int32 cast wraps modulo "
        "2**32: the same int32"
    ),
    "lab0_interop:render_rotating_triangle:cmp_GtE_Gt:0": (
        "only pixel centres whose barycentric rounds to exactly 0 change, within 1e-4 pixel of an "
        "edge, which the contract lets go either way (the docstring says so)"
    ),
    "lab0_interop:render_rotating_triangle:const_int:9": (
        "inside pixels have barycentrics >= 0 summing to 1, so none exceeds 1 beyond rounding (far "
        "below 0.5/255); outside pixels take the background: the upper clamp never changes a code"
    ),
    "lab0_interop:run_frame_loop:const_int:2": (
        "a third device framebuffer is allocated but never used (only indices i % 2 and 0 are read)"
    ),
    "lab0_interop:FrameDownloader:op_Add_Sub:0": (
        "(slot - 1) % n walks the ring backwards: any cyclic order reuses a slot only n submits "
        "later, while at most n - 1 others are pending (FIFO through pending), so the frames "
        "received and the buffers reused are the same; for n = 1, 2 identical"
    ),
    "lab0_interop:measure_copy_bandwidth:const_int:0": (
        "a default of 6 repeats instead of 5 only changes how long the measurement runs"
    ),
    "lab0_interop:pack_rgba8:const_int:11": (
        "word >= 2**32 never matches (words < 2**32), but the int64 -> int32 cast wraps modulo "
        "2**32 on CPU and CUDA, giving the same two's-complement word"
    ),
    "lab0_interop:run_frame_loop:const_int:4": (
        "without overlap the loop renders into framebuffers[1] instead of framebuffers[0]: both are"
        " allocated alike (shape, dtype, device) and the other is never used"
    ),
    "lab0_interop:pack_rgba8:cmp_GtE_Gt:0": (
        "torch's int64 -> int32 conversion keeps the low 32 bits (two's complement) on the CPU"
        " and on CUDA, and the mutated expression equals the reference modulo 2**32 for every "
        "word, so no uint8 input tells it apart"
    ),
    "lab0_interop:pack_rgba8:cmp_GtE_LtE:0": (
        "torch's int64 -> int32 conversion keeps the low 32 bits (two's complement) on the CPU"
        " and on CUDA, and the mutated expression equals the reference modulo 2**32 for every "
        "word, so no uint8 input tells it apart"
    ),
    "lab0_interop:pack_rgba8:const_int:13": (
        "torch's int64 -> int32 conversion keeps the low 32 bits (two's complement) on the CPU"
        " and on CUDA, and the mutated expression equals the reference modulo 2**32 for every "
        "word, so no uint8 input tells it apart (word - 2**33 = word - 2**32 modulo 2**32)"
    ),
    "lab0_interop:pack_rgba8:swap_where:0": (
        "torch's int64 -> int32 conversion keeps the low 32 bits (two's complement) on the CPU"
        " and on CUDA, and the mutated expression equals the reference modulo 2**32 for every "
        "word, so no uint8 input tells it apart"
    ),
    "lab0_interop:cuda_array_interface:cmp_NotEq_Eq:1": (
        "CUDA only: the function raises ValueError for a CPU framebuffer before this line, so "
        "only a CUDA framebuffer reaches the stream value"
    ),
    "lab0_interop:cuda_array_interface:const_int:0": (
        "CUDA only: the function raises ValueError for a CPU framebuffer before building the "
        "dict (version)"
    ),
    "lab0_interop:cuda_array_interface:const_int:1": (
        "CUDA only: the function raises ValueError for a CPU framebuffer before this line, so "
        "only a CUDA framebuffer reaches the stream value"
    ),
    "lab0_interop:cuda_array_interface:const_int:2": (
        "CUDA only: the function raises ValueError for a CPU framebuffer before this line, so "
        "only a CUDA framebuffer reaches the stream value"
    ),
    "lab0_interop:measure_copy_bandwidth:bool_And_Or:1": (
        "non_blocking only changes when the copy may return: on the CPU a copy is synchronous "
        "whatever the flag, and time_fn synchronises the device, so only the measured time (a "
        "timing, not pinned by any test) can differ"
    ),
    "lab0_interop:linear_to_srgb8:drop_clamp:0": (
        "the clamp after nan_to_num is redundant: srgb_encode does the same itself: its "
        "docstring (course.core.image.srgb_encode, which the task docstring names as the srgb "
        'to use): "Inputs are clamped to [0, 1] first (displays cannot show more) and NaN '
        'becomes 0"'
    ),
    "lab0_interop:linear_to_srgb8:drop_nan_to_num:0": (
        "clamp(0, 1) alone sends -inf to 0 and +inf to 1; NaN stays NaN and srgb_encode does "
        "the same itself: its docstring (course.core.image.srgb_encode, which the task "
        'docstring names as the srgb to use): "Inputs are clamped to [0, 1] first (displays '
        'cannot show more) and NaN becomes 0"'
    ),
    "lab0_interop:render_rotating_triangle:drop_clamp:0": (
        "pixels outside (a negative weight) are replaced by the background; inside pixels have"
        " three weights >= 0 summing to 1 up to rounding, so each is at most 1 + a few ulp and"
        " floor(255 w + 0.5) gives the same code with or without the clamp"
    ),
}
