"""Fused Triton and CUDA kernels and their BVH: what the labs' torch code is measured by."""
