"""ffexp: force-control experiments on free-floating objects.

See README.md for the quick start, docs/architecture.md for the architecture and
docs/conventions.md for frames, signs and units. Importing the package imports
nothing else (the command line starts fast); the modules import what they need.
"""

__version__ = "0.1.0"
