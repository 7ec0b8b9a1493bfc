"""Run the `flexlink` command line as ``python -m flexlink_ros.cli``."""

import sys

from .main import main

sys.exit(main())
