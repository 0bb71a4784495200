"""treegen: Weber-Penn trees for game engines."""

from .blas_kernel import pin_kernel as _pin_kernel

_pin_kernel()  # before anything imports numpy: byte-identical outputs across x86-64 machines
__version__ = "0.1.0"
