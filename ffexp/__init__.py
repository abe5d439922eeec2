"""ffexp: force-control experiments on free-floating objects.

See README.md for the quick start and ../shared/design for the architecture.
"""

__version__ = "0.1.0"
