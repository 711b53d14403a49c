"""What labs and kernels are measured with: timing, op and register counts, occupancy."""
