"""fdem: hybrid finite-discrete element solver for jointed rock slopes."""
__version__ = "0.1.0"
