"""GPU ray tracing with PyTorch: the course package, in rooms whose imports point down.

From the floor up: core (the framework every lab uses); given (each lab's given code) and
measure (timing, op counts, occupancy), which import core only; kernels (the fused
references); grading (the autograder); tools (rtcourse and what it builds). A room imports
only rooms below it (tests/meta/test_import_graph.py holds the table).
"""

__version__ = "0.1.0"
