"""parcelfit: calibrate physics simulations of parcels with flexible packaging.

The pipeline: track videos -> runs -> reference run per test case -> simulate ->
screen -> calibrate -> report. See the README for the command line.
"""

from parcelfit.errors import ParcelfitError

__all__ = ["ParcelfitError", "__version__"]
__version__ = "0.1.0"
