"""Run the `flexlink` command line as ``python -m flexlink_ros.cli``."""

from .main import run

run()
