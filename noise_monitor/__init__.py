"""noise_monitor: online camera noise source estimation (Full-Meta) and diagnosis for ROS 2."""

__version__ = "0.1.0"
