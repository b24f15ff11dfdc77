"""The version of nlcx (one home: the package, its manifests and ``nlcx --version`` read it)."""

__version__ = "0.1.0"
