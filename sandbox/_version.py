"""The version of sandbox (one place; the package, the CLI and the stores read it)."""

__version__ = "0.1.0"
