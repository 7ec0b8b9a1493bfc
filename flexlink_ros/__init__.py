"""flexlink_ros: elastic deflection and joint-contact estimates of a flexible four-bar linkage."""

__version__ = '0.1.0'
