"""Monte Carlo error budgets for boresight calibration of strapdown electro-optical sensors."""

__version__ = "0.1.0"
