"""wtinspect: offline perception and planning for drone inspection of wind turbines."""

__version__ = "0.1.0"
