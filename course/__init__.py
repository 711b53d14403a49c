"""GPU ray tracing with PyTorch: the framework every lab uses."""

__version__ = "0.1.0"
