"""tracker: real-time model-based tracking of articulated bodies from calibrated cameras."""

__version__ = "0.1.0"
