"""opticalstamp: design and analysis of lensless contact image scanners (optical stamps)."""

__version__ = "0.1.0"
