"""Native acceleration of the simulator: the compiled C library (built on first use, loaded with
ctypes), the fused no-grad pixel steps and the chunk-at-a-time stepping of an event list.

Every path here gives the torch path's results bit for bit; without a C compiler the simulator
falls back to torch. This package imports nothing itself.
"""

__all__: list[str] = []
