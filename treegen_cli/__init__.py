"""treegen: Weber-Penn trees for game engines."""
__version__ = "0.1.0"
